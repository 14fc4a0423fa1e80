"""LiDAR virtual camera: field of view, camera choice, z-buffer == reference, hidden points."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

from nbcalib.camera import create_camera
from nbcalib.errors import InputError
from nbcalib.preprocess import lidar_image as li
from nbcalib.preprocess.intensity import equalize_point_intensities
from nbcalib.preprocess.lidar_image import (
    estimate_lidar_fov,
    make_virtual_camera,
    render_lidar_image,
    visible_mask,
)
from nbcalib.reference import zbuffer as ref
from nbcalib.transforms import make_T, so3_exp

# ------------------------------------------------------------------------------------------
# helpers

JIT_OFF = os.environ.get("NUMBA_DISABLE_JIT") == "1"  # coverage runs: kernels in Python


def _cameras():
    """A pinhole and an equirectangular virtual camera (small) and a distorted real camera."""
    pinhole, T_pin = make_virtual_camera(math.radians(90.0), pinhole_size=64)
    equirect, T_eq = make_virtual_camera(math.pi, equirectangular_size=(96, 48))
    real = create_camera(
        "plumb_bob", [40.0, 42.0, 31.5, 23.5], [-0.2, 0.05, 1e-3, -2e-3, 0.0], 64, 48
    )
    T_real = make_T(so3_exp([0.1, -0.2, 0.05]) @ T_pin[:3, :3], [0.05, -0.1, 0.02])
    fisheye = create_camera("fisheye", [20.0, 20.0, 31.5, 23.5], [0.01, -0.01, 0.0, 0.0], 64, 48)
    return {
        "pinhole": (pinhole, T_pin),
        "equirectangular": (equirect, T_eq),
        "plumb_bob": (real, T_real),
        "fisheye": (fisheye, T_pin),
    }


CAMERAS = _cameras()


def _nasty_cloud(rng, camera, T_camera_lidar, n=400):
    """Random points plus NaN rows, points behind the camera, border pixels and exact ties."""
    points = rng.normal(scale=3.0, size=(n, 3))
    points[rng.random(n) < 0.05] = np.nan  # NaN rows
    points[:5, 0] = np.inf
    # quantised ranges: many exact ties of depth within a pixel
    points[n // 2 :] = np.round(points[n // 2 :] * 4) / 4
    # exact duplicates (same pixel, same range): the larger index must win
    points[-20:-10] = points[-10:]
    # points whose pixel position is exactly on the image border
    T_lidar_camera = np.linalg.inv(T_camera_lidar)
    border_uv = np.array(
        [
            [-0.5, 10.0],
            [camera.width - 0.5, 10.0],
            [10.0, -0.5],
            [10.0, camera.height - 0.5],
            [-0.5, -0.5],
            [camera.width - 0.5 - 1e-9, camera.height - 0.5 - 1e-9],
        ]
    )
    bearings = camera.unproject(border_uv)
    border = (bearings[np.all(np.isfinite(bearings), axis=1)] * 2.0) @ T_lidar_camera[:3, :3].T
    border += T_lidar_camera[:3, 3]
    return np.vstack([points, border, border])  # border twice: exact ties as well


def _kernel(camera, T, points):
    best, index, pixel, range2 = li._zbuffer(
        camera, np.ascontiguousarray(T, float), np.ascontiguousarray(points, float)
    )
    shape = (camera.height, camera.width)
    return best.reshape(shape), index.reshape(shape), pixel, range2


# ------------------------------------------------------------------------------------------
# z-buffer kernel == reference


@pytest.mark.parametrize("name", list(CAMERAS))
def test_zbuffer_kernel_equals_reference(name, rng):
    camera, T = CAMERAS[name]
    for _ in range(3):
        points = _nasty_cloud(rng, camera, T)
        expected = ref.render_zbuffer(
            camera.model_id, camera.params, T, points, camera.width, camera.height
        )
        got = _kernel(camera, T, points)
        assert len(got) == len(expected) == 4
        for e, g in zip(expected, got):
            assert e.dtype == g.dtype
            assert np.array_equal(e, g)
        assert (got[1] >= 0).sum() > 20  # the test sees filled pixels


@pytest.mark.parametrize("name", list(CAMERAS))
def test_render_lidar_image_equals_reference(name, rng):
    camera, T = CAMERAS[name]
    points = _nasty_cloud(rng, camera, T)
    values = rng.random(len(points))
    image = render_lidar_image(camera, T, points, values)
    best, index, _, _ = ref.render_zbuffer(
        camera.model_id, camera.params, T, points, camera.width, camera.height
    )
    assert np.array_equal(image.index, index)
    assert np.array_equal(image.depth, np.sqrt(best).astype(np.float32))
    expected = np.where(index >= 0, np.rint(255 * values[index]), 0).astype(np.uint8)
    assert np.array_equal(image.intensity, expected)
    assert image.intensity.dtype == np.uint8 and image.index.dtype == np.int32
    assert image.depth.dtype == np.float32
    assert np.all(np.isinf(image.depth[index < 0]))


def test_empty_cloud():
    camera, T = CAMERAS["pinhole"]
    image = render_lidar_image(camera, T, np.zeros((0, 3)), np.zeros(0))
    assert image.index.shape == (camera.height, camera.width)
    assert np.all(image.index == -1) and np.all(image.intensity == 0)
    assert np.all(np.isinf(image.depth))
    assert visible_mask(camera, T, np.zeros((0, 3))).shape == (0,)


def test_tie_rule_larger_index_wins_and_nearest_wins():
    camera, T = CAMERAS["pinhole"]
    # LiDAR +x is the optical axis: these all land in the same (central) pixel
    points = np.array([[5.0, 0, 0], [3.0, 0, 0], [3.0, 0, 0], [4.0, 0, 0]])
    image = render_lidar_image(camera, T, points, np.array([0.1, 0.2, 0.3, 0.4]))
    filled = np.argwhere(image.index >= 0)
    assert len(filled) == 1
    r, c = filled[0]
    assert (r, c) == (32, 32)  # principal point 31.5: floor(31.5 + 0.5)
    assert image.index[r, c] == 2  # range 3 twice: the larger index
    assert image.depth[r, c] == np.float32(3.0)
    assert image.intensity[r, c] == round(255 * 0.3)


def test_border_pixels_follow_the_rounding_convention():
    # fx = 32, cx = 31.5 (the 90-degree virtual camera, exactly): x/z = -1 gives u = -0.5
    # exactly (first column), x/z = +1 gives u = 63.5 = W - 0.5 (off the image)
    _, T = make_virtual_camera(math.radians(90.0), pinhole_size=64)
    camera = create_camera("pinhole", [32.0, 32.0, 31.5, 31.5], [], 64, 64)
    # camera x = -LiDAR y, camera z = LiDAR x
    points = np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 0.0, 1.0], [1.0, 0.0, -1.0]])
    _, _, pixel, _ = _kernel(camera, T, points)
    row_mid = int(np.floor(31.5 + 0.5))
    assert pixel[0] == row_mid * 64 + 0  # u = -0.5 -> column 0
    assert pixel[1] == -1  # u = 63.5 -> off
    assert pixel[2] == 0 * 64 + row_mid  # v = -0.5 -> row 0
    assert pixel[3] == -1  # v = 63.5 -> off


def test_behind_camera_and_invalid_points_are_skipped():
    camera, T = CAMERAS["pinhole"]
    points = np.array([[-5.0, 0, 0], [np.nan, 0, 0], [0.0, 0, 0], [1e200, 0, 0]])
    _, index, pixel, range2 = _kernel(camera, T, points)
    assert np.all(pixel == -1) and np.all(np.isinf(range2)) and np.all(index == -1)


def test_inputs_are_validated():
    camera, T = CAMERAS["pinhole"]
    with pytest.raises(ValueError, match="points_lidar"):
        render_lidar_image(camera, T, np.zeros((3, 2)), np.zeros(3))
    with pytest.raises(ValueError, match="intensities"):
        render_lidar_image(camera, T, np.zeros((3, 3)), np.zeros(2))
    with pytest.raises(ValueError, match="finite"):
        render_lidar_image(camera, T, np.zeros((1, 3)), np.array([np.nan]))
    with pytest.raises(ValueError, match="T_camera_lidar"):
        render_lidar_image(camera, np.eye(3), np.zeros((1, 3)), np.zeros(1))
    with pytest.raises(ValueError, match="window"):
        visible_mask(camera, T, np.zeros((1, 3)), window=-1)


# ------------------------------------------------------------------------------------------
# hidden-point removal


@pytest.mark.parametrize("window", [0, 1, 2])
@pytest.mark.parametrize("name", ["pinhole", "plumb_bob", "equirectangular"])
def test_visible_mask_equals_reference(name, window, rng):
    camera, T = CAMERAS[name]
    points = _nasty_cloud(rng, camera, T, n=600)
    expected = ref.visible_mask(
        camera.model_id, camera.params, T, points, camera.width, camera.height, 0.3, window
    )
    got = visible_mask(camera, T, points, margin=0.3, window=window)
    assert np.array_equal(got, expected)
    assert 0 < got.sum() < len(points)


@pytest.mark.parametrize("name", list(CAMERAS))
def test_float32_points_are_the_float64_cloud_bit_for_bit(name, rng):
    """A work directory's float32 cloud goes in without a float64 copy: the same answers."""
    from nbcalib.preprocess.lidar_image import visibility

    camera, T = CAMERAS[name]
    cloud = _nasty_cloud(rng, camera, T)
    rows = np.column_stack([cloud, rng.random(len(cloud))]).astype(np.float32)
    points32 = rows[:, :3]  # as a work directory's cloud is read: a view of x, y, z, intensity
    points64 = points32.astype(np.float64)
    assert not points32.flags.c_contiguous
    for w in (0, 2):
        got, want = (visibility(camera, T, p, margin=0.3, window=w) for p in (points32, points64))
        assert all(np.array_equal(g, e) for g, e in zip(got, want))
        assert 0 < got[0].size < len(points32)
    values = rng.random(len(points32))
    a, b = (render_lidar_image(camera, T, p, values) for p in (points32, points64))
    for field in ("index", "depth", "intensity"):
        assert np.array_equal(getattr(a, field), getattr(b, field))


def test_visible_mask_hides_a_wall_behind_a_board():
    camera, T = make_virtual_camera(math.radians(60.0), pinhole_size=64)
    g = np.linspace(-1.5, 1.5, 121)
    yy, zz = np.meshgrid(g, g)
    wall = np.column_stack([np.full(yy.size, 10.0), yy.ravel(), zz.ravel()])
    # a board at 5 m covering the same directions as the wall's centre |y|, |z| < 0.5
    board = wall[(np.abs(wall[:, 1]) < 0.5) & (np.abs(wall[:, 2]) < 0.5)] * 0.5
    points = np.vstack([wall, board])
    visible = visible_mask(camera, T, points, margin=0.1)
    is_board = np.arange(len(points)) >= len(wall)
    assert visible[is_board].all()
    behind = ~is_board & (np.abs(points[:, 1]) < 0.4) & (np.abs(points[:, 2]) < 0.4)
    assert not visible[behind].any()  # hidden by the board, 5 m nearer
    outside = ~is_board & ((np.abs(points[:, 1]) > 0.7) | (np.abs(points[:, 2]) > 0.7))
    assert visible[outside].all()
    # a wider window also hides the wall points right next to the board's edge
    edge = ~is_board & (np.abs(points[:, 1]) < 0.55) & (np.abs(points[:, 2]) < 0.55)
    assert visible[edge].sum() > visible_mask(camera, T, points, margin=0.1, window=2)[edge].sum()


# ------------------------------------------------------------------------------------------
# field of view


def _cone(rng, half_angle, n, *, axis=(1.0, 0.0, 0.0)):
    """Directions uniformly in a cone of ``half_angle`` around ``axis``, at random ranges."""
    cos_t = rng.uniform(math.cos(half_angle), 1.0, n)
    phi = rng.uniform(0, 2 * math.pi, n)
    sin_t = np.sqrt(1 - cos_t**2)
    local = np.column_stack([cos_t, sin_t * np.cos(phi), sin_t * np.sin(phi)])
    # rotate e_x onto axis
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    v = np.cross([1.0, 0, 0], a)
    if np.linalg.norm(v) < 1e-12:
        R = np.eye(3) if a[0] > 0 else np.diag([-1.0, -1.0, 1.0])
    else:
        R = so3_exp(v / np.linalg.norm(v) * math.acos(np.clip(a[0], -1, 1)))
    return local @ R.T * rng.uniform(2.0, 40.0, (n, 1))


def _brute_force_fov(points):
    d = points / np.linalg.norm(points, axis=1, keepdims=True)
    return math.acos(np.clip((d @ d.T).min(), -1, 1))


@pytest.mark.parametrize("half_deg", [5.0, 35.0, 70.0, 85.0, 120.0])
def test_fov_of_a_cone_is_exact(half_deg, rng):
    points = _cone(rng, math.radians(half_deg), 3000, axis=(1.0, 0.3, -0.2))
    fov = estimate_lidar_fov(points, voxel_size=0.0)
    assert fov == pytest.approx(_brute_force_fov(points), abs=1e-12)
    assert fov <= 2 * math.radians(half_deg) + 1e-9


def test_fov_kd_tree_path_equals_brute_force(rng, monkeypatch):
    monkeypatch.setattr(li, "_BRUTE_FORCE_MAX", 10)
    for half_deg in (20.0, 80.0, 110.0, 179.0):
        points = _cone(rng, math.radians(half_deg), 2000)
        assert estimate_lidar_fov(points, voxel_size=0.0) == pytest.approx(
            _brute_force_fov(points), abs=1e-9
        )


def test_fov_counts_points_inside_the_hull_of_the_points(rng):
    """The reference's hull-of-the-points shortcut underestimates this wide field of view."""
    # three far clusters 120 degrees apart around the sensor, one near cluster behind it
    clusters = []
    for azimuth_deg, distance in [(0, 10.0), (120, 10.0), (-120, 10.0), (180, 2.0)]:
        a = math.radians(azimuth_deg)
        centre = distance * np.array([math.cos(a), math.sin(a), 0.0])
        spread = 0.3 if distance > 5 else 0.1
        clusters.append(centre + rng.uniform(-spread, spread, size=(50, 3)))
    cloud = np.vstack(clusters)
    from scipy.spatial import ConvexHull

    facets = ConvexHull(np.vstack(clusters[:3])).equations  # outward normals n, offsets b
    inside = clusters[3] @ facets[:, :3].T + facets[:, 3] < 0
    assert inside.all()  # the near points lie inside the hull of the far ones
    vertices = cloud[ConvexHull(cloud).vertices]
    assert _brute_force_fov(vertices) < math.radians(140.0)  # the reference: a pinhole camera
    fov = estimate_lidar_fov(cloud, voxel_size=0.0)
    assert fov == pytest.approx(_brute_force_fov(cloud), abs=1e-12)
    assert fov > math.radians(165.0)  # nbcalib: equirectangular


def test_fov_downsampling_and_min_range(rng):
    points = _cone(rng, math.radians(40.0), 20000)
    fov = estimate_lidar_fov(points)
    assert fov == pytest.approx(math.radians(80.0), abs=math.radians(1.0))
    # points within 1 m are ignored, non-finite rows too
    noisy = np.vstack([points, [[0.0, 0.5, 0.0], [-0.5, 0, 0], [np.nan, 1, 1]]])
    assert estimate_lidar_fov(noisy) == fov


def test_fov_of_a_spinning_lidar_is_near_180_degrees(rng):
    az = rng.uniform(-math.pi, math.pi, 20000)
    el = rng.uniform(math.radians(-25), math.radians(3), 20000)
    r = rng.uniform(3, 60, 20000)
    points = np.column_stack(
        [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), r * np.sin(el)]
    )
    assert math.degrees(estimate_lidar_fov(points)) > 178.0


def test_fov_degenerate_inputs(rng):
    with pytest.raises(InputError, match="only 2 points"):
        estimate_lidar_fov(np.array([[5.0, 0, 0], [0, 5.0, 0], [0.1, 0, 0]]))
    with pytest.raises(InputError, match="only 0 points"):
        estimate_lidar_fov(np.full((10, 3), np.nan))
    # a 2-D scanner: every point in the plane z = 0 through the sensor
    planar = np.column_stack([rng.normal(size=(500, 2)) * 10, np.zeros(500)])
    with pytest.raises(InputError, match="one plane through the sensor"):
        estimate_lidar_fov(planar)
    # a plane *not* through the sensor (a wall) is fine
    wall = np.column_stack([np.full(500, 5.0), rng.normal(size=(500, 2))])
    assert 0 < estimate_lidar_fov(wall, voxel_size=0.0) < math.pi / 2
    with pytest.raises(ValueError):
        estimate_lidar_fov(np.zeros((5, 2)))


# ------------------------------------------------------------------------------------------
# virtual camera


def test_pinhole_virtual_camera():
    fov = math.radians(70.0)
    camera, T = make_virtual_camera(fov)
    assert camera.model == "pinhole" and (camera.width, camera.height) == (1024, 1024)
    f = 1024 / (2 * math.tan(fov / 2))
    assert np.allclose(camera.intrinsics, [f, f, 511.5, 511.5], rtol=0, atol=1e-12)
    assert np.array_equal(T[:3, 3], np.zeros(3)) and np.allclose(np.linalg.det(T[:3, :3]), 1)
    # LiDAR +x at the image centre, LiDAR +y (left) to the left, +z (up) at the top
    p_lidar = np.array([[10.0, 0, 0], [10.0, 1.0, 0], [10.0, 0, 1.0]])
    uv, valid = camera.project(p_lidar @ T[:3, :3].T)
    assert valid.all()
    assert np.allclose(uv[0], [511.5, 511.5])
    assert uv[1, 0] < 511.5 and uv[1, 1] == 511.5
    assert uv[2, 1] < 511.5 and uv[2, 0] == 511.5
    # a point at half the field of view off-axis lands on the image border
    edge = [math.cos(fov / 2), math.sin(fov / 2), 0.0]
    assert camera.project(T[:3, :3] @ edge)[0][0] == pytest.approx(-0.5)


def test_equirectangular_virtual_camera():
    camera, T = make_virtual_camera(math.radians(150.0))
    assert camera.model == "equirectangular" and (camera.width, camera.height) == (1920, 960)
    R = T[:3, :3]
    # (the poles themselves have no longitude: just off them)
    uv, valid = camera.project(
        np.array([[1.0, 0, 0], [0, 1.0, 0], [1e-9, 0, 1.0], [1e-9, 0, -1.0]]) @ R.T
    )
    assert valid.all()
    assert uv[0, 0] == pytest.approx(0.75 * 1920 - 0.5)  # LiDAR +x
    assert uv[0, 1] == pytest.approx(480 - 0.5)  # on the horizon
    assert uv[1, 0] == pytest.approx(960 - 0.5)  # LiDAR +y at the centre column
    assert uv[2, 1] == pytest.approx(-0.5, abs=1e-6)  # up at the top
    assert uv[3, 1] == pytest.approx(960 - 0.5, abs=1e-6)  # down at the bottom
    # configurable resolutions and threshold
    small, _ = make_virtual_camera(math.radians(170.0), equirectangular_size=(400, 200))
    assert (small.width, small.height) == (400, 200)
    pin, _ = make_virtual_camera(math.radians(100.0), pinhole_size=256, pinhole_max_fov_deg=90)
    assert pin.model == "equirectangular"
    with pytest.raises(ValueError):
        make_virtual_camera(0.0)


# ------------------------------------------------------------------------------------------
# real data


@pytest.mark.realdata
@pytest.mark.skipif(JIT_OFF, reason="120 000 points through the z-buffer in pure Python")
def test_render_a_real_kitti_scan(real_data, tmp_path):
    import cv2

    scan = np.fromfile(
        real_data / "kitti_raw_2011_09_26" / "0000000000" / "velodyne.bin", dtype=np.float32
    ).reshape(-1, 4)
    points = scan[:, :3].astype(np.float64)
    fov = estimate_lidar_fov(points)
    assert math.degrees(fov) > 170.0  # HDL-64E: 360 degrees around
    camera, T_vcam_lidar = make_virtual_camera(fov)
    assert camera.model == "equirectangular"
    image = render_lidar_image(camera, T_vcam_lidar, points, equalize_point_intensities(scan[:, 3]))
    filled = image.index >= 0
    rows = np.flatnonzero(filled.any(axis=1))
    # 64 beams from +2 to -24.8 degrees: rows of the upper-middle band only
    lat_top = 0.5 - (rows.min() + 0.5) / 960  # latitude / pi of the highest filled row
    lat_bottom = 0.5 - (rows.max() + 0.5) / 960
    assert 0.0 < math.degrees(lat_top * math.pi) < 10.0  # +6.6 degrees in this scan
    assert -30.0 < math.degrees(lat_bottom * math.pi) < -20.0
    assert filled.sum() > 0.5 * len(points) * 0.5  # z-buffer keeps a large share of points
    assert filled.any(axis=0).mean() > 0.95  # every azimuth is seen
    # the rendered ranges are the points' ranges
    hit = image.index[filled]
    assert np.allclose(image.depth[filled], np.linalg.norm(points[hit], axis=1), rtol=1e-6)
    out = Path(os.environ.get("NBCALIB_TEST_OUTPUT", tmp_path)) / "kitti_lidar_image.png"
    cv2.imwrite(str(out), image.intensity)
