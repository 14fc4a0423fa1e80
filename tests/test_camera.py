"""Camera models: kernels vs slow references, vs OpenCV, round trips, Jacobians, invalid points."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib import reference
from nbcalib.camera import (
    CAMERA_MODELS,
    CameraModel,
    camera_from_camera_info,
    camera_from_opencv,
    camera_to_camera_info,
    create_camera,
)
from nbcalib.reference import camera as ref
from tests.tolerances import TOL

assert reference  # the package exists

#: Realistic cameras, one per model, whose whole image lies in the model's domain.
CAMERAS = {
    "pinhole": ("pinhole", [500.0, 510.0, 319.5, 239.5], [], 640, 480),
    "plumb_bob": (
        "plumb_bob",
        [721.5, 721.5, 609.6, 172.9],
        [-0.28, 0.07, 0.0012, -0.0005, -0.008],
        1242,
        375,
    ),
    "rational_polynomial": (
        "rational_polynomial",
        [1000.0, 1000.0, 959.5, 599.5],
        [2.0, 0.5, 0.0005, -0.0003, 0.01, 2.3, 0.9, 0.05],
        1920,
        1200,
    ),
    "fisheye": ("fisheye", [380.0, 381.0, 639.5, 479.5], [0.05, -0.01, 0.002, -0.0005], 1280, 960),
    "atan": ("atan", [400.0, 400.0, 319.5, 239.5], [0.9], 640, 480),
    "omnidir": (
        "omnidir",
        [700.0, 702.0, 639.5, 479.5, 1.2],
        [-0.2, 0.05, 0.001, 0.0005],
        1280,
        960,
    ),
    "equirectangular": ("equirectangular", [1920.0, 960.0], [], 1920, 960),
}


def make(name: str) -> CameraModel:
    return create_camera(*CAMERAS[name])


def points_in_view(cam: CameraModel, rng, n=2000, in_image=True):
    """Random points whose projections fall inside the image (from random pixels and depths)."""
    uv = np.column_stack(
        [rng.uniform(-0.5, cam.width - 0.5, n), rng.uniform(-0.5, cam.height - 0.5, n)]
    )
    bearings = cam.unproject(uv)
    keep = np.isfinite(bearings[:, 0])
    depth = rng.uniform(0.5, 50.0, keep.sum())
    return bearings[keep] * depth[:, None], uv[keep]


def test_all_models_listed():
    assert set(CAMERAS) == set(CAMERA_MODELS)


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_kernel_matches_reference(name, rng):
    cam = make(name)
    pts, _ = points_in_view(cam, rng)
    uv, valid = cam.project(pts)
    assert valid.all()
    expected = ref.project(
        cam.model, cam.intrinsics, cam.distortion_coeffs, cam.width, cam.height, pts
    )
    assert_allclose(uv, expected, rtol=1e-12, atol=1e-9)


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_roundtrip_over_whole_image(name):
    """project(unproject(uv)) == uv at every 3rd pixel and along all four borders."""
    cam = make(name)
    grid = cam.pixel_grid(step=3)
    w, h = cam.width, cam.height
    eps = 1e-6  # the image's outer edge itself; for equirectangular -0.5 is the pole
    lo, hu, hv = -0.5 + eps, w - 0.5 - eps, h - 0.5 - eps
    border = np.concatenate(
        [
            np.column_stack([np.linspace(lo, hu, 500), np.full(500, lo)]),
            np.column_stack([np.linspace(lo, hu, 500), np.full(500, hv)]),
            np.column_stack([np.full(500, lo), np.linspace(lo, hv, 500)]),
            np.column_stack([np.full(500, hu), np.linspace(lo, hv, 500)]),
        ]
    )
    uv = np.concatenate([grid, border])
    bearings = cam.unproject(uv)
    assert np.isfinite(bearings).all(), "every pixel of these cameras is inside the model domain"
    assert_allclose(np.linalg.norm(bearings, axis=1), 1.0, atol=1e-12)
    uv2, valid = cam.project(bearings)
    assert valid.all()
    assert_allclose(uv2, uv, **TOL["camera_roundtrip_px"])


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_unproject_matches_numeric_reference(name, rng):
    """The closed forms / Newton steps agree with a generic numerical inverse."""
    cam = make(name)
    uv = np.column_stack([rng.uniform(0, cam.width - 1, 25), rng.uniform(0, cam.height - 1, 25)])
    expected = ref.unproject(
        cam.model, cam.intrinsics, cam.distortion_coeffs, cam.width, cam.height, uv
    )
    assert np.isfinite(expected).all()
    assert_allclose(cam.unproject(uv), expected, atol=1e-9)


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_unproject_project_recovers_rays(name, rng):
    cam = make(name)
    pts, _ = points_in_view(cam, rng)
    uv, valid = cam.project(pts)
    assert valid.all()
    assert_allclose(cam.unproject(uv), pts / np.linalg.norm(pts, axis=1, keepdims=True), atol=1e-9)


@pytest.mark.parametrize("name", ["plumb_bob", "rational_polynomial", "pinhole"])
def test_matches_opencv_project_points(name, rng):
    cam = make(name)
    pts, _ = points_in_view(cam, rng)
    D = np.zeros(8)
    D[: cam.distortion_coeffs.size] = cam.distortion_coeffs
    expected, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), cam.K, D)
    uv, _ = cam.project(pts)
    assert_allclose(uv, expected.reshape(-1, 2), **TOL["camera_vs_opencv_px"])


def test_fisheye_matches_opencv(rng):
    cam = make("fisheye")
    pts, _ = points_in_view(cam, rng)
    front = pts[pts[:, 2] > 0.05 * np.linalg.norm(pts, axis=1)]  # cv2.fisheye needs z > 0
    expected, _ = cv2.fisheye.projectPoints(
        front.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), cam.K, cam.distortion_coeffs
    )
    uv, valid = cam.project(front)
    assert valid.all()
    assert_allclose(uv, expected.reshape(-1, 2), **TOL["camera_vs_opencv_px"])
    # OpenCV's undistortPoints is the inverse (normalised x / z); its solver is reliable only
    # well inside 90 degrees, so compare there
    moderate = front[:, 2] > np.linalg.norm(front, axis=1) * math.cos(math.radians(60))
    und = cv2.fisheye.undistortPoints(
        uv[moderate].reshape(-1, 1, 2), cam.K, cam.distortion_coeffs, criteria=(3, 100, 1e-14)
    ).reshape(-1, 2)
    b = cam.unproject(uv[moderate])
    assert_allclose(b[:, :2] / b[:, 2:], und, atol=1e-7)


def test_plumb_bob_unproject_matches_opencv_undistort(rng):
    cam = make("plumb_bob")
    uv = np.column_stack([rng.uniform(0, cam.width, 200), rng.uniform(0, cam.height, 200)])
    und = cv2.undistortPoints(
        uv.reshape(-1, 1, 2), cam.K, cam.distortion_coeffs, criteria=(3, 200, 1e-15)
    ).reshape(-1, 2)
    b = cam.unproject(uv)
    assert_allclose(b[:, :2] / b[:, 2:], und, atol=1e-7)


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_jacobian_matches_finite_differences(name, rng):
    cam = make(name)
    pts, _ = points_in_view(cam, rng, n=400)
    # near the optical axis the fisheye and atan kernels switch to series expansions
    axis = np.array([[1e-7, -2e-7, 1.5], [0.0, 0.0, 2.0], [3e-5, 1e-5, 1.0]])
    if name != "equirectangular":
        pts = np.concatenate([pts, axis])
    uv, J, valid = cam.project_jacobian(pts)
    assert valid.all()
    uv_only, _ = cam.project(pts)
    assert_allclose(uv, uv_only, rtol=0, atol=0)
    numeric = ref.project_jacobian_numeric(
        cam.model, cam.intrinsics, cam.distortion_coeffs, cam.width, cam.height, pts
    )
    scale = np.maximum(1.0, np.abs(numeric).max(axis=(1, 2), keepdims=True))
    assert_allclose(J / scale, numeric / scale, **TOL["jacobian_vs_finite_diff"])


@pytest.mark.parametrize("name", [m for m in CAMERA_MODELS if m != "equirectangular"])
def test_intrinsics_jacobian_matches_finite_differences(name, rng):
    """d(u, v) / d(fx, fy, cx, cy) of every model against central differences of the
    projection with each intrinsic moved (issue 47: the focal length refined with the pose)."""
    cam = make(name)
    pts, _ = points_in_view(cam, rng, n=300)
    uv, J, valid = cam.intrinsics_jacobian(pts)
    assert valid.all() and J.shape == (len(pts), 2, 4)
    assert_allclose(uv, cam.project(pts)[0], rtol=0, atol=0)
    numeric = np.empty_like(J)
    for k in range(4):
        h = 1e-4 * max(1.0, abs(cam.intrinsics[k]))
        moved = []
        for sign in (1.0, -1.0):
            intr = np.array(cam.intrinsics, dtype=np.float64)
            intr[k] += sign * h
            other = create_camera(cam.model, intr, cam.distortion_coeffs, cam.width, cam.height)
            moved.append(other.project(pts)[0])
        numeric[:, :, k] = (moved[0] - moved[1]) / (2 * h)
    assert_allclose(J, numeric, rtol=1e-6, atol=1e-7)
    with pytest.raises(ValueError, match="equirectangular"):
        make("equirectangular").intrinsics_jacobian(pts[:3])


def test_series_branches_are_continuous():
    """fisheye and atan switch to series near the axis; values agree across the switch."""
    for name in ("fisheye", "atan"):
        cam = make(name)
        z = 1.0
        rho = np.array([0.99999e-4, 1.00001e-4]) * (1.0 if name == "fisheye" else 1 / 0.2)
        pts = np.column_stack([rho, np.zeros(2), np.full(2, z)])
        uv, J, _ = cam.project_jacobian(pts)
        slope = (uv[1, 0] - uv[0, 0]) / (rho[1] - rho[0])
        assert abs(slope - J[0, 0, 0]) < 1e-4 * abs(J[0, 0, 0])


def test_atan_has_no_jump_at_small_radius():
    """The reference switches distortion off below r = 1e-3; nbcalib is continuous there."""
    cam = make("atan")
    x = np.array([0.999e-3, 1.001e-3])
    uv, _ = cam.project(np.column_stack([x, np.zeros(2), np.ones(2)]))
    du = uv[1, 0] - uv[0, 0]
    assert 0 < du < 1e-5 * cam.intrinsics[0] * 2.5


# ------------------------------------------------------------------------------ invalid points


@pytest.mark.parametrize("name", ["pinhole", "plumb_bob", "rational_polynomial", "atan"])
def test_points_behind_are_invalid(name):
    cam = make(name)
    pts = np.array([[0.1, 0.1, -1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.1, 0.2, -1e-9]])
    uv, valid = cam.project(pts)
    assert not valid.any()
    assert np.isnan(uv).all()


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_non_finite_points_are_invalid(name):
    cam = make(name)
    pts = np.array([[np.nan, 0, 1], [0, np.inf, 1], [0.1, 0.1, -np.inf], [np.nan] * 3])
    _, valid = cam.project(pts)
    _, _, valid_j = cam.project_jacobian(pts)
    assert not valid.any() and not valid_j.any()


def test_fisheye_never_folds_points_from_behind():
    """The reference uses |z|: a point behind would land where its mirror image does."""
    cam = make("fisheye")
    centre = cam.intrinsics[2:4]
    # 105 degrees off the axis, behind but inside the lens' domain (122.7 degrees): it must land
    # further out than its mirror image in front (75 degrees)
    (uv_f,), (ok_f,) = cam.project([[1.0, 0.5, 0.3]])
    (uv_b,), (ok_b,) = cam.project([[1.0, 0.5, -0.3]])
    assert ok_f and ok_b
    assert np.linalg.norm(uv_b - centre) > np.linalg.norm(uv_f - centre) + 100.0
    # 160 degrees off the axis, beyond the domain: invalid, not folded onto its mirror image
    assert cam.project([[0.3, 0.2, 1.0]])[1][0]
    assert not cam.project([[0.3, 0.2, -1.0]])[1][0]
    assert not cam.project([0.0, 0.0, -1.0])[1]
    # a theta limit: beyond where theta_d stops growing, points are invalid
    narrow = create_camera("fisheye", [300, 300, 320, 240], [-0.3, 0.02, 0, 0], 640, 480)
    theta_max = narrow.params[13]
    assert theta_max < math.pi
    t = theta_max + 0.05
    assert not narrow.project([math.sin(t), 0.0, math.cos(t)])[1]
    assert narrow.project([math.sin(t - 0.1), 0.0, math.cos(t - 0.1)])[1]


def test_barrel_distortion_beyond_fold_is_invalid():
    """Strong barrel distortion: r * radial(r) peaks, and points beyond would fold back inward."""
    cam = create_camera("plumb_bob", [500, 500, 320, 240], [-0.4, 0.0, 0, 0, 0], 640, 480)
    r_fold = 1 / math.sqrt(3 * 0.4)  # d/dr (r - 0.4 r^3) = 0
    assert_allclose(math.sqrt(cam.params[13]), r_fold, rtol=1e-9)
    _, valid = cam.project([[0.9 * r_fold, 0, 1], [1.1 * r_fold, 0, 1], [3 * r_fold, 0, 1]])
    assert valid.tolist() == [True, False, False]


def test_omnidir_visible_cap():
    full = create_camera("omnidir", [300, 300, 320, 240, 1.0], [], 640, 480)
    assert full.project([[0.1, 0.0, -0.99]])[1][0]  # xi = 1: all but the antipode
    assert not full.project([[0.0, 0.0, -1.0]])[1][0]
    for xi in (0.5, 2.0):
        cam = create_camera("omnidir", [300, 300, 320, 240, xi], [], 640, 480)
        zmin = -min(xi, 1 / xi)
        inside = np.array([[math.sqrt(1 - (zmin + 0.01) ** 2), 0, zmin + 0.01]])
        outside = np.array([[math.sqrt(1 - (zmin - 0.01) ** 2), 0, zmin - 0.01]])
        assert cam.project(inside)[1][0]
        assert not cam.project(outside)[1][0]


def test_equirectangular_known_answers():
    cam = make("equirectangular")
    W, H = cam.width, cam.height
    pts = np.array([[0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, -1, 1e-12], [0, 1, 1e-12], [0, -0.5, 1]])
    uv, valid = cam.project(pts)
    assert valid.all()
    assert_allclose(uv[0], [W / 2 - 0.5, H / 2 - 0.5])  # optical axis: image centre
    assert_allclose(uv[1, 0], 0.75 * W - 0.5)  # +x (right) a quarter turn to the right
    assert_allclose(uv[2, 0], 0.25 * W - 0.5)
    assert_allclose(uv[3, 1], -0.5, atol=1e-6)  # straight up (-y): top edge
    assert_allclose(uv[4, 1], H - 0.5, atol=1e-6)
    assert uv[5, 1] < H / 2
    assert not cam.project([0.0, 1.0, 0.0])[1]  # exactly at a pole: no longitude


def test_in_image_and_project_in_image():
    cam = make("pinhole")
    uv = np.array([[-0.5, -0.5], [639.49, 479.49], [639.5, 0], [0, -0.51]])
    assert cam.in_image(uv).tolist() == [True, True, False, False]
    pts = cam.unproject(np.array([[10.0, 10.0], [100, 100]]))
    pts = np.concatenate([pts, [[5.0, 0.0, 1.0]]])  # far to the right, valid but off-image
    assert cam.project(pts)[1].tolist() == [True, True, True]
    assert cam.project(pts, in_image=True)[1].tolist() == [True, True, False]


def test_single_point_shapes():
    cam = make("plumb_bob")
    uv, valid = cam.project([0.1, 0.2, 3.0])
    assert uv.shape == (2,) and bool(valid)
    assert cam.unproject(uv).shape == (3,)
    _, J, _ = cam.project_jacobian([0.1, 0.2, 3.0])
    assert J.shape == (2, 3)


def test_fov():
    cam = create_camera("pinhole", [500, 500, 319.5, 239.5], [], 640, 480)
    half_diag = math.atan(math.hypot(320, 240) / 500)
    assert_allclose(cam.max_angle_rad, half_diag, rtol=1e-6)
    assert_allclose(cam.fov_deg, 2 * math.degrees(half_diag), rtol=1e-6)
    assert make("equirectangular").fov_deg == 360.0
    assert make("fisheye").fov_deg > 180.0  # this lens sees behind its image plane
    kitti = make("plumb_bob")  # barrel distortion: the corners see furthest
    corners = np.array([[-0.5, -0.5], [1241.5, -0.5], [-0.5, 374.5], [1241.5, 374.5]]) - 1e-9
    widest = np.arccos(kitti.unproject(corners)[:, 2].min())
    assert_allclose(kitti.max_angle_rad, widest, rtol=1e-6)


# ------------------------------------------------------------------------------ construction


@pytest.mark.parametrize(
    "args, match",
    [
        (("kannala", [1, 1, 0, 0], [], 10, 10), "unknown camera model"),
        (("plumb_bob", [1, 1, 0], [0] * 5, 10, 10), r"'plumb_bob' takes 4 intrinsics"),
        (("plumb_bob", [1, 1, 0, 0], [0] * 4, 10, 10), r"takes 5 distortion coefficients"),
        (("omnidir", [1, 1, 0, 0], [0] * 4, 10, 10), r"'omnidir' takes 5 intrinsics"),
        (("fisheye", [1, 1, 0, 0], [0] * 5, 10, 10), r"'fisheye' takes 4 distortion"),
        (("pinhole", [1, 1, 0, 0], [0.1], 10, 10), r"'pinhole' takes 0 distortion"),
        (("pinhole", [0, 1, 0, 0], [], 10, 10), "focal lengths must be > 0"),
        (("pinhole", [-1, 1, 0, 0], [], 10, 10), "focal lengths must be > 0"),
        (("pinhole", [np.nan, 1, 0, 0], [], 10, 10), "must be finite"),
        (("plumb_bob", [1, 1, 0, 0], [np.inf, 0, 0, 0, 0], 10, 10), "must be finite"),
        (("pinhole", [1, 1, 0, 0], [], 0, 10), "image size"),
        (("pinhole", [1, 1, 0, 0], [], 10.5, 10), "image size"),
        (("equirectangular", [100, 50], [], 100, 60), "equal to the image size"),
        (("atan", [1, 1, 0, 0], [4.0], 10, 10), "omega"),
        (("omnidir", [1, 1, 0, 0, -1], [0] * 4, 10, 10), "xi"),
        (("pinhole", "abc", [], 10, 10), "must be numbers"),
    ],
)
def test_bad_parameters_raise(args, match):
    with pytest.raises(ValueError, match=match):
        create_camera(*args)


def test_bad_shapes_raise():
    cam = make("pinhole")
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        cam.project(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        cam.unproject(np.zeros((4, 3)))


def test_aliases_and_empty_distortion():
    cam = create_camera("EQUIDISTANT", [300, 300, 320, 240], None, 640, 480)
    assert cam.model == "fisheye" and cam.distortion_coeffs.tolist() == [0.0] * 4


def test_dict_roundtrip_and_equality():
    for name in CAMERA_MODELS:
        cam = make(name)
        again = CameraModel.from_dict(cam.to_dict())
        assert again == cam and hash(again) == hash(cam)
        assert name in repr(cam)
    with pytest.raises(ValueError, match="lacks width, height"):
        CameraModel.from_dict({"camera_model": "pinhole", "intrinsics": [1, 1, 0, 0]})


def test_parameters_are_immutable():
    cam = make("plumb_bob")
    with pytest.raises(ValueError):
        cam.params[0] = 1.0
    with pytest.raises(AttributeError):
        cam.width = 5


def test_from_opencv():
    K = np.array([[700.0, 0, 600], [0, 710.0, 180], [0, 0, 1]])
    assert camera_from_opencv(K, None, 1242, 375).model == "pinhole"
    assert camera_from_opencv(K, np.zeros(5), 1242, 375).model == "pinhole"
    c4 = camera_from_opencv(K, [0.1, 0.01, 0.001, 0.002], 1242, 375)
    assert c4.model == "plumb_bob" and c4.distortion_coeffs.tolist() == [0.1, 0.01, 0.001, 0.002, 0]
    c8 = camera_from_opencv(K, [0.1, 0.01, 0, 0, 0, 0.2, 0, 0], 1242, 375)
    assert c8.model == "rational_polynomial"
    assert camera_from_opencv(K, [0.1, 0, 0, 0, 0, 0, 0, 0], 1242, 375).model == "plumb_bob"
    assert camera_from_opencv(K, [0.1, 0.0, 0, 0], 1242, 375, fisheye=True).model == "fisheye"
    with pytest.raises(ValueError, match="thin-prism"):
        camera_from_opencv(K, [0.1] * 12, 1242, 375)
    with pytest.raises(ValueError, match="no skew"):
        skewed = K.copy()
        skewed[0, 1] = 1.0
        camera_from_opencv(skewed, None, 1242, 375)


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_camera_info_roundtrip(name):
    cam = make(name)
    info = camera_to_camera_info(cam)
    again = camera_from_camera_info(
        **{k: info[k] for k in ("width", "height", "distortion_model", "D", "K")}
    )
    uv = cam.pixel_grid(step=97)
    assert_allclose(again.unproject(uv), cam.unproject(uv), atol=1e-12)
    if name in ("plumb_bob", "rational_polynomial"):
        assert info["distortion_model"] == name
    if name == "fisheye":
        assert info["distortion_model"] == "equidistant"


def test_camera_info_from_message_object():
    class Msg:  # ROS2 field names, as rosbags decodes them
        width, height = 1242, 375
        distortion_model = "plumb_bob"
        d = np.zeros(5)
        k = np.array([721.5, 0, 609.6, 0, 721.5, 172.9, 0, 0, 1])

    cam = camera_from_camera_info(Msg())
    assert cam.model == "plumb_bob" and cam.intrinsics.tolist() == [721.5, 721.5, 609.6, 172.9]
    # zero-padded D (some drivers publish 8 entries for plumb_bob)
    cam = camera_from_camera_info(
        width=10, height=10, distortion_model="plumb_bob", D=[0.1, 0, 0, 0, 0, 0, 0, 0], K=np.eye(3)
    )
    assert cam.distortion_coeffs.size == 5


def _nearest_pixels_reference(cam, T, pts):
    """Slow: project each point, round with floor(u + 0.5), -1 when invalid or off-image."""
    with np.errstate(invalid="ignore"):
        pc = pts @ T[:3, :3].T + T[:3, 3]
    uv, valid = cam.project(pc)
    out = np.full(len(pts), -1, dtype=np.int64)
    for i, ((u, v), ok) in enumerate(zip(uv, valid)):
        if ok:
            iu, iv = math.floor(u + 0.5), math.floor(v + 0.5)
            if 0 <= iu < cam.width and 0 <= iv < cam.height:
                out[i] = iv * cam.width + iu
    return out


@pytest.mark.parametrize("name", CAMERA_MODELS)
def test_nearest_pixels_matches_project_point(name, rng):
    """The vectorised block projection gives the pixels and validity of project_point, also on
    pixel borders, behind the camera, beyond the distortion fold and for non-finite points."""
    from nbcalib.kernels.projection_batch import nearest_pixels
    from nbcalib.transforms import se3_exp

    cam = make(name)
    inside, _ = points_in_view(cam, rng, 1500)
    # points whose pixels lie exactly on rounding borders (u + 0.5 an integer) and image edges
    uv = np.column_stack(
        [rng.integers(0, cam.width, 300) - 0.5, rng.integers(0, cam.height, 300) + 0.0]
    )
    uv[:20, 0] = cam.width - 0.5
    uv[20:40, 1] = cam.height - 0.5
    b = cam.unproject(uv)
    border = b[np.isfinite(b[:, 0])] * 3.0
    wide = rng.normal(size=(800, 3)) * [3.0, 3.0, 1.0]  # many behind the camera or far outside
    odd = np.array(
        [[np.nan, 0, 1], [0, 0, -5], [0, 0, 0], [np.inf, 1, 1], [1, -np.inf, 2], [0, 1, 0]]
    )
    pts = np.concatenate([inside, border, wide, odd])
    for T in (np.eye(4), se3_exp(np.array([0.02, -0.01, 0.03, 0.01, -0.02, 0.015]))):
        expected = _nearest_pixels_reference(cam, T, pts)
        out = np.empty(len(pts), dtype=np.int32)
        x, y, z = (np.ascontiguousarray(pts[:, k]) for k in range(3))
        nearest_pixels(cam.model_id, cam.params, T, x, y, z, cam.width, cam.height, -1, out)
        assert np.array_equal(out, expected)
        assert (out >= 0).sum() > 1000
        assert (out < 0).sum() > (2 if name == "equirectangular" else 100)


def test_nearest_pixels_beyond_fold_and_cap():
    from nbcalib.kernels.projection_batch import nearest_pixels

    barrel = create_camera("plumb_bob", [500, 500, 320, 240], [-0.4, 0.0, 0, 0, 0], 640, 480)
    r_fold = 1 / math.sqrt(3 * 0.4)
    omni = create_camera("omnidir", [300, 300, 320, 240, 0.5], [], 640, 480)
    zmin = -0.5
    cases = [
        (barrel, [[0.9 * r_fold, 0, 1], [1.1 * r_fold, 0, 1], [3 * r_fold, 0, 1]]),
        (omni, [[math.sqrt(1 - (zmin + 0.01) ** 2), 0, zmin + 0.01], [0.87, 0, -0.51]]),
    ]
    for cam, pts in cases:
        pts = np.asarray(pts, dtype=np.float64)
        out = np.empty(len(pts), dtype=np.int32)
        x, y, z = (np.ascontiguousarray(pts[:, k]) for k in range(3))
        nearest_pixels(cam.model_id, cam.params, np.eye(4), x, y, z, cam.width, cam.height, -1, out)
        assert np.array_equal(out, _nearest_pixels_reference(cam, np.eye(4), pts))
