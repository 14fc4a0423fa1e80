"""The synthetic rig: scenes, motion, LiDAR patterns and distortion, cameras, ground truth."""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.kernels.raycast import PRIM_MATERIAL, PRIM_SIZE
from nbcalib.kernels.synthetic_texture import LUMA
from nbcalib.synthetic import (
    LIDAR_PRESETS,
    Material,
    MotionConfig,
    RenderConfig,
    RigConfig,
    SceneBuilder,
    camera_lidar_overlap,
    default_T_camera_lidar,
    generate_sequence,
    lidar_preset,
    make_scene,
    make_trajectory,
    render_image,
    simulate_scan,
)
from nbcalib.synthetic.effects import EFFECTS, lidar_without, render_without
from nbcalib.synthetic.render import radiance
from nbcalib.synthetic.scene import Lighting
from nbcalib.synthetic.texture import surface_properties
from nbcalib.transforms import interpolate_pose, invert_T, make_T, transform_points

SMALL = (160, 120)


def _small(lidar="spinning64", camera="pinhole", **kw) -> RigConfig:
    """A quick configuration: small image, fewer columns, a few scans."""
    overrides = {"columns": 256} if LIDAR_PRESETS[lidar].kind == "spinning" else {}
    return RigConfig(
        lidar=lidar,
        camera=camera,
        image_size=SMALL,
        lidar_config=lidar_preset(lidar, **overrides),
        **{"duration": 0.3, **kw},
    )


def _box_room():
    """Four walls, a floor and a ceiling: every LiDAR point lies on one of six planes."""
    b = SceneBuilder()
    m = b.material(Material("checker", 0.5, (0.8, 0.8, 0.8), (0.2, 0.2, 0.2), 0.8, 0.2))
    b.rectangle((4, 0, 0), (0, 1, 0), (0, 0, 1), (5, 3), m)
    b.rectangle((-3, 0, 0), (0, 1, 0), (0, 0, 1), (5, 3), m)
    b.rectangle((0, 5, 0), (1, 0, 0), (0, 0, 1), (5, 3), m)
    b.rectangle((0, -4, 0), (1, 0, 0), (0, 0, 1), (5, 3), m)
    b.rectangle((0, 0, -1.5), (1, 0, 0), (0, 1, 0), (5, 5), m)
    b.rectangle((0, 0, 2.5), (1, 0, 0), (0, 1, 0), (5, 5), m)
    planes = [(0, 4.0), (0, -3.0), (1, 5.0), (1, -4.0), (2, -1.5), (2, 2.5)]
    return b.build(), planes


def _plane_distance(points_world, planes):
    return np.min([np.abs(points_world[:, axis] - c) for axis, c in planes], axis=0)


# --- scenes ----------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["room", "street"])
def test_scenes_are_seeded_and_keep_the_rig_free(kind, rng):
    a, b, c = (make_scene(kind=kind, seed=s) for s in (7, 7, 8))
    assert_array_equal(a.prims, b.prims)
    assert_array_equal(a.materials, b.materials)
    assert a.prims.shape != c.prims.shape or not np.array_equal(a.prims, c.prims)
    assert len(a.prims) > 30
    # nothing within ~1 m of the rig: the nearest surface in any direction is the floor / road
    directions = rng.normal(size=(20_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = a.cast(np.zeros(3), directions)
    assert hits.t[hits.hit].min() > 1.1
    kinds = {int(k) for k in a.prims[:, 0]}
    assert kinds == {0, 1, 2, 3}  # rectangles, boxes, cylinders, ellipsoids


# --- motion ----------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["nod", "drive", "static"])
def test_trajectory_starts_at_rest_at_identity(kind):
    config = MotionConfig(kind=kind, seed=3)
    traj = make_trajectory(config, 2.0)
    assert_allclose(traj.pose(0.0), np.eye(4), atol=1e-15)
    at_rest = traj.poses(np.linspace(0.0, config.rest, 20))
    assert_allclose(at_rest, np.broadcast_to(np.eye(4), at_rest.shape), atol=1e-15)
    later = traj.pose(1.5)
    moved = np.linalg.norm(later[:3, 3]) + np.linalg.norm(later[:3, :3] - np.eye(3))
    assert (moved > 0.05) == (kind != "static")
    if kind == "drive":
        assert later[0, 3] > 1.0  # forward along LiDAR x


def test_trajectory_interpolates_between_knots_as_conventions_say():
    traj = make_trajectory(MotionConfig(kind="nod", seed=1, knot_interval=0.05), 2.0)
    k = 20
    T0, T1 = traj.pose(traj.times[k]), traj.pose(traj.times[k + 1])
    s = np.array([0.0, 0.25, 0.5, 0.9])
    want = interpolate_pose(T0, T1, s)
    got = traj.poses(traj.times[k] + s * (traj.times[k + 1] - traj.times[k]))
    assert_allclose(got, want, atol=1e-12)


# --- LiDAR patterns --------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["spinning16", "spinning32", "spinning64", "spinning128"])
def test_spinning_pattern(name):
    lidar = LIDAR_PRESETS[name]
    directions, times, rings = lidar.pattern(0.0)
    assert len(times) == lidar.beams * lidar.columns
    assert np.all(np.diff(times) >= 0) and times[0] == 0 and times[-1] < lidar.scan_period
    assert_array_equal(np.unique(rings), np.arange(lidar.beams))
    elevation = np.degrees(np.arcsin(directions[:, 2]))
    assert_allclose([elevation.min(), elevation.max()], lidar.vertical_fov_deg, atol=1e-9)
    # ring 0 is the lowest beam; one column per azimuth step
    assert_allclose(elevation[rings == 0], lidar.vertical_fov_deg[0], atol=1e-9)
    azimuth = np.degrees(np.arctan2(directions[rings == 0, 1], directions[rings == 0, 0]))
    step = np.abs(np.diff(np.unwrap(np.radians(azimuth))))
    assert_allclose(np.degrees(step), lidar.azimuth_resolution_deg, rtol=1e-9)


def test_rosette_fills_its_field_of_view_over_time():
    """Coverage of 0.2-degree cells grows scan by scan, as a Livox: ~20 % in 0.1 s, ~all in 2 s."""
    lidar = LIDAR_PRESETS["livox"]
    half_h, half_v = np.radians(lidar.fov_deg) / 2
    bins_h, bins_v = (round(f / 0.2) for f in lidar.fov_deg)
    ch = (np.arange(bins_h) + 0.5) / bins_h * 2 - 1
    cv = (np.arange(bins_v) + 0.5) / bins_v * 2 - 1
    inside = (ch[None, :] ** 2 + cv[:, None] ** 2) <= 0.95
    covered = np.zeros((bins_v, bins_h), dtype=bool)
    coverage = []
    for k in range(20):  # 2 s, scan by scan
        directions, times, _ = lidar.pattern(k * lidar.scan_period)
        assert np.all(np.diff(times) > 0)  # strictly increasing: one point at a time
        azimuth = np.arctan2(directions[:, 1], directions[:, 0])
        elevation = np.arcsin(directions[:, 2])
        assert np.all((azimuth / half_h) ** 2 + (elevation / half_v) ** 2 <= 1.0 + 1e-12)
        i = np.clip(((azimuth / half_h + 1) / 2 * bins_h).astype(int), 0, bins_h - 1)
        j = np.clip(((elevation / half_v + 1) / 2 * bins_v).astype(int), 0, bins_v - 1)
        covered[j, i] = True
        coverage.append(covered[inside].mean())
    coverage = np.array(coverage)
    assert np.all(np.diff(coverage) > 0)
    assert 0.1 < coverage[0] < 0.3 and coverage[9] > 0.8 and coverage[19] > 0.95
    # non-repetitive: the next scan is not the same pattern
    d0, _, _ = lidar.pattern(0.0)
    d1, _, _ = lidar.pattern(lidar.scan_period)
    assert d0.shape != d1.shape or not np.allclose(d0, d1)


# --- motion distortion -----------------------------------------------------------------------
def test_deskewing_with_the_true_trajectory_recovers_the_static_scene():
    scene, planes = _box_room()
    lidar = lidar_preset("spinning32", columns=512, range_noise=0.0, dropout=0.0)
    motion = MotionConfig(kind="nod", rest=0.0, ramp=0.05, nod_amplitude_deg=25.0, nod_period=1.0)
    trajectory = make_trajectory(motion, 1.0)
    rng = np.random.default_rng(0)
    for t_start in (0.3, 0.6):
        scan = simulate_scan(scene, lidar, trajectory, t_start, rng)
        assert len(scan) > 0.9 * lidar.points_per_scan
        assert np.all(np.diff(scan.times) >= 0) and scan.times[-1] < lidar.scan_period
        # each point from the pose at its own time lands on a wall
        poses = trajectory.poses(scan.stamp + scan.times)
        world = np.einsum("nij,nj->ni", poses[:, :3, :3], scan.points) + poses[:, :3, 3]
        assert _plane_distance(world, planes).max() < 1e-9
        # the ground-truth undistorted points are the same points in the scan-start frame
        T_begin = trajectory.pose(scan.stamp)
        assert_allclose(transform_points(T_begin, scan.points_undistorted), world, atol=1e-9)
        # the raw (distorted) sweep placed with one pose does not fit the walls
        naive = transform_points(T_begin, scan.points)
        assert np.percentile(_plane_distance(naive, planes), 90) > 0.05


def test_static_scans_need_no_deskewing():
    seq = generate_sequence(_small("livox", duration=0.2))
    assert len(seq.scans) >= 2
    for scan in seq.scans:
        assert_allclose(scan.points, scan.points_undistorted, atol=1e-12)
        assert np.all(np.diff(scan.times) > 0)
        assert scan.rings.dtype == np.uint16 and scan.rings.max() < 6
        assert np.all((scan.intensities >= 0) & (scan.intensities <= 255))


def test_noise_and_dropouts_follow_the_config():
    scene, planes = _box_room()
    trajectory = make_trajectory(MotionConfig(kind="static"), 0.2)
    quiet = lidar_preset("spinning64", columns=512, range_noise=0.0, dropout=0.0)
    noisy = lidar_preset("spinning64", columns=512, range_noise=0.03, dropout=0.2)
    a = simulate_scan(scene, quiet, trajectory, 0.0, np.random.default_rng(1))
    b = simulate_scan(scene, noisy, trajectory, 0.0, np.random.default_rng(1))
    assert_allclose(len(b) / len(a), 0.8, atol=0.02)
    residual = _plane_distance(b.points, planes)
    assert 0.015 < np.median(residual) < 0.03  # |N(0, 3 cm)| projected on the walls
    # intensity falls with incidence: the floor seen at 4-5 m is darker than the wall at 4 m
    distance = np.linalg.norm(a.points, axis=1)
    ahead = (np.abs(a.points[:, 0] - 4.0) < 1e-6) & (np.abs(a.points[:, 2]) < 0.3)
    floor = (np.abs(a.points[:, 2] + 1.5) < 1e-6) & (distance > 4.0) & (distance < 5.0)
    assert a.intensities[ahead].mean() > 1.5 * a.intensities[floor].mean()


# --- cameras: the LiDAR points land on the surfaces the camera sees --------------------------
@pytest.mark.parametrize("model", CAMERA_MODELS)
def test_lidar_points_land_on_what_the_camera_sees(model):
    seq = generate_sequence(_small("spinning64", model, duration=0.2, seed=4))
    points, _ = seq.dense_cloud()
    prim = np.concatenate([s.prim for s in seq.scans])
    p_camera = transform_points(seq.T_camera_lidar, points)
    uv, valid = seq.camera.project(p_camera, in_image=True)
    assert valid.sum() > 500
    pixel = np.floor(uv[valid] + 0.5).astype(int)
    seen_prim = seq.rendered.prim[pixel[:, 1], pixel[:, 0]]
    seen_range = seq.rendered.range[pixel[:, 1], pixel[:, 0]]
    lidar_range = np.linalg.norm(p_camera[valid], axis=1)
    same = seen_prim == prim[valid]
    # occlusion edges and the camera-LiDAR parallax leave a few points on other surfaces
    assert same.mean() > 0.85
    relative = np.abs(seen_range[same] - lidar_range[same]) / lidar_range[same]
    assert np.median(relative) < 0.01


def test_rendering_kernel_matches_the_building_blocks(rng):
    """The fused shading kernel = cast + textures + shadow rays through the public pieces."""
    scene = make_scene(kind="street", seed=2)
    camera = example_camera("pinhole", *SMALL)
    bearings = camera.unproject(camera.pixel_grid())
    directions = bearings @ np.array([[0, 0, 1.0], [-1, 0, 0], [0, -1, 0]]).T
    angle = 1.0 / camera.intrinsics[0]
    light, t, prim = radiance(scene, np.zeros(3), directions, angle)
    light_par, _, _ = radiance(scene, np.zeros(3), directions, angle, parallel=True)
    assert_array_equal(light, light_par)
    hits = scene.cast(np.zeros(3), directions)
    assert_array_equal(prim, hits.prim)
    assert_allclose(t[hits.hit], hits.t[hits.hit], rtol=0, atol=0)
    albedo, _, _, _ = scene.surface_properties(
        hits, footprint=scene.footprint(hits, directions, angle)
    )
    h = hits.hit
    points = hits.t[h, None] * directions[h] + 1e-4 * hits.normal[h]
    sun = np.asarray(scene.lighting.sun_direction)
    facing = hits.normal[h] @ sun
    shadowed = scene.occluded(points, np.broadcast_to(sun, points.shape), np.inf)
    irradiance = scene.lighting.ambient * (0.7 + 0.3 * hits.normal[h, 2])
    irradiance += np.where((facing > 0) & ~shadowed, facing, 0.0) * scene.lighting.sun_irradiance
    assert_allclose(light[h], albedo[h] * irradiance[:, None], rtol=1e-12, atol=1e-12)
    assert 0.05 < shadowed[facing > 0].mean() < 0.95  # there are shadows, not only shadows


@pytest.mark.parametrize("color", [False, True])
def test_images_are_grey_or_colour_with_black_outside_the_lens(color):
    scene = make_scene(kind="room", seed=1)
    camera = example_camera("fisheye", *SMALL)
    image = render_image(scene, camera, make_T(np.eye(3), np.zeros(3)), RenderConfig(color=color))
    assert image.image.dtype == np.uint8
    assert image.image.shape == ((120, 160, 3) if color else (120, 160))
    outside = ~np.isfinite(image.bearings[..., 0])
    assert np.all(image.image[outside] == 0) and np.all(np.isnan(image.range[outside]))
    inside = image.image[~outside]
    assert inside.std() > 15  # texture and shading, not a flat picture


# --- the whole rig ---------------------------------------------------------------------------
@pytest.mark.parametrize("lidar", list(LIDAR_PRESETS))
@pytest.mark.parametrize("scene", ["room", "street"])
def test_default_rigs_overlap(lidar, scene):
    """For every default rig the camera sees a good part of what the LiDAR sees."""
    for seed in range(3):
        config = _small(lidar, scene=scene, seed=seed, duration=0.5)
        overlap = camera_lidar_overlap(generate_sequence(config), cell_px=8)
        assert overlap["image_coverage"] > 0.5, (seed, overlap)
        assert overlap["points_in_image"] > (0.5 if lidar == "livox" else 0.05), (seed, overlap)


def test_default_ground_truth_is_like_a_real_rig():
    offsets, forward = [], []
    for seed in range(40):
        T_lidar_camera = invert_T(default_T_camera_lidar("spinning", seed))
        offsets.append(np.linalg.norm(T_lidar_camera[:3, 3]))
        forward.append(T_lidar_camera[:3, 2])  # the optical axis in the LiDAR frame
    offsets, forward = np.array(offsets), np.array(forward)
    assert offsets.min() >= 0.05 and offsets.max() <= 0.30
    assert np.all(np.abs(forward[:, 2]) < np.sin(np.radians(11)))  # roughly level
    assert forward[:, 0].min() < -0.5 and np.abs(forward[:, 1]).max() > 0.9  # backwards, sideways
    rosette = invert_T(default_T_camera_lidar("rosette", 3))
    assert rosette[0, 2] > np.cos(np.radians(12))  # looks into the rosette's field of view


def test_same_seed_same_output_and_parallel_equals_serial():
    config = _small("spinning64", "omnidir", seed=9, duration=0.2)
    a = generate_sequence(config)
    b = generate_sequence(config)
    c = generate_sequence(RigConfig(**{**config.__dict__, "parallel": True}))
    for other in (b, c):
        assert_array_equal(a.image, other.image)
        assert_array_equal(a.T_camera_lidar, other.T_camera_lidar)
        for s, t in zip(a.scans, other.scans):
            for field in ("points", "intensities", "times", "rings", "points_undistorted"):
                assert_array_equal(getattr(s, field), getattr(t, field))
    d = generate_sequence(RigConfig(**{**config.__dict__, "seed": 10}))
    assert not np.array_equal(a.image, d.image)
    # pairs share the rig, not the scene
    e = generate_sequence(config, pair=1)
    assert_array_equal(a.T_camera_lidar, e.T_camera_lidar)
    assert not np.array_equal(a.scene.prims[:5], e.scene.prims[:5])


def test_sequence_poses_and_stamps():
    seq = generate_sequence(_small("spinning16", duration=0.5, seed=2))
    lidar = seq.lidar
    assert len(seq.scans) == 5
    assert_allclose(seq.scan_stamps, np.arange(5) * lidar.scan_period)
    assert_allclose(seq.scan_poses_begin[0], np.eye(4), atol=1e-15)
    assert_allclose(seq.scan_poses_end[:-1], seq.scan_poses_begin[1:], atol=1e-12)
    # the first scan is taken at rest: undistorted = distorted, like the image
    assert_allclose(seq.scans[0].points, seq.scans[0].points_undistorted, atol=1e-12)
    assert_allclose(seq.T_lidar_camera @ seq.T_camera_lidar, np.eye(4), atol=1e-12)


def _digest(seq) -> str:
    import hashlib

    h = hashlib.sha256(seq.image.tobytes())
    for scan in seq.scans:
        for array in (scan.points, scan.intensities, scan.times, scan.rings):
            h.update(np.ascontiguousarray(array).tobytes())
    return h.hexdigest()


def test_parallel_with_more_threads_than_cores_equals_serial():
    import subprocess
    import sys
    from pathlib import Path

    code = (
        "import sys; sys.path.insert(0, 'tests'); import test_synthetic as t; "
        "from nbcalib.synthetic import RigConfig, generate_sequence; "
        "c = t._small('spinning32', 'fisheye', seed=3, duration=0.2); "
        "print(t._digest(generate_sequence(RigConfig(**{**c.__dict__, 'parallel': True}))))"
    )
    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "NUMBA_NUM_THREADS": "5"}
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=root, env=env, capture_output=True, text=True, check=True
    )
    serial = generate_sequence(_small("spinning32", "fisheye", seed=3, duration=0.2))
    assert out.stdout.strip() == _digest(serial)


# --- switching single camera/LiDAR differences off (RigConfig.without) -----------------------
#: the switches that change the camera image, and those that change the LiDAR scans
CAMERA_EFFECTS = {"shading", "shadows", "camera-texture", "optics"}
LIDAR_EFFECTS = {"lidar-texture", "materials", "elements", "lidar-noise", "lidar-falloff"}

#: sha256 of the image and the points as written (x, y, z, intensity, t, ring), recorded with the
#: code before the switches existed (c6007d7): the default output must not change, bit for bit
GOLDEN = {
    "room": "5909669f68e33924339036f5c12aa5cb507472fe8abc27bd3b1b285fc66ac694",
    "street": "c9baa35cee1e4443ccf592d9561f9b4ff34e7aad570fdc1b0adad084f2715a60",
    "street_gap": "50e0df9b7a15bb6879ab0603794df3022973693e7ccbb1128fbf9f01db7d764f",
}
GOLDEN_CONFIGS = {
    "room": dict(
        lidar="spinning16",
        camera="fisheye",
        duration=0.3,
        lidar_config=lidar_preset("spinning16", columns=180),
        seed=5,
        color=True,
    ),
    "street": dict(lidar="livox", scene="street", duration=0.2, seed=3),
    "street_gap": dict(
        lidar="spinning32",
        scene="street",
        duration=0.2,
        lidar_config=lidar_preset("spinning32", columns=256),
        seed=2,
        modality_gap=0.4,
        color=True,
    ),
}


def _written_digest(seq) -> str:
    import hashlib

    from nbcalib.synthetic.writer import scan_fields

    h = hashlib.sha256(np.ascontiguousarray(seq.image).tobytes())
    for scan in seq.output_scans():
        fields = scan_fields(scan, time_offset=scan.stamp)
        for key in ("x", "y", "z", "intensity", "t", "ring"):
            h.update(np.ascontiguousarray(fields[key]).tobytes())
    return h.hexdigest()


@pytest.mark.parametrize("name", GOLDEN)
def test_the_default_is_todays_output_bit_for_bit(name):
    """Nothing switched off: the same image and points as before the switches existed.

    The digests hash what the writer writes (8-bit pixels, float32 points), recorded on Linux
    x86-64; re-record them only for a deliberate change of the rig's default output.
    """
    config = RigConfig(image_size=(96, 72), **GOLDEN_CONFIGS[name])
    assert config.without == ()
    assert _written_digest(generate_sequence(config)) == GOLDEN[name]
    assert _written_digest(generate_sequence(replace(config, without=""))) == GOLDEN[name]


def test_effects_are_checked_and_kept_in_order():
    assert set(EFFECTS) == CAMERA_EFFECTS | LIDAR_EFFECTS | {"motion"}
    assert RigConfig(without="optics, shading,optics").without == ("shading", "optics")
    assert RigConfig(without=["motion", "shadows"]).without == ("shadows", "motion")
    with pytest.raises(ValueError, match="unknown effect 'shade'; expected some of shading, "):
        RigConfig(without=("shade",))
    render = render_without(RenderConfig(), ("shading", "shadows", "optics"))
    assert not render.shading and not render.shadows
    assert render.blur_sigma_px == render.read_noise == render.shot_noise == 0.0
    lidar = lidar_without(LIDAR_PRESETS["livox"], ("lidar-noise", "lidar-falloff"))
    assert lidar.range_noise == lidar.intensity_noise == lidar.dropout == 0.0
    assert lidar.beam_divergence == lidar.incidence_exponent == lidar.range_exponent == 0.0
    assert render_without(RenderConfig(), ("materials",)) == RenderConfig()
    assert lidar_without(LIDAR_PRESETS["livox"], ("optics",)) is LIDAR_PRESETS["livox"]


@pytest.mark.parametrize("effect", EFFECTS)
def test_each_switch_changes_its_own_sensor_only(effect):
    """Every random draw stays in place: a switch changes the image or the scans, not both."""
    config = _small("spinning16", seed=6, duration=0.2)
    base = generate_sequence(config)
    seq = generate_sequence(replace(config, without=(effect,)))
    assert seq.config.without == (effect,)
    image_changed = not np.array_equal(seq.image, base.image)
    scans_changed = any(
        not np.array_equal(a.points, b.points) or not np.array_equal(a.intensities, b.intensities)
        for a, b in zip(seq.scans, base.scans)
    )
    assert image_changed == (effect in CAMERA_EFFECTS)
    assert scans_changed == (effect in LIDAR_EFFECTS)
    assert (len(seq.output_scans()) == 1) == (effect == "motion")  # what is written


def _texture_probe(without, gap=1.0) -> dict:
    """Albedo and reflectivity ``(N, 3), (N,)`` at fixed spots: a plain material (``"plain"``),
    a brick wall (``"bricks"``), and within a single brick of it (``"brick"``)."""
    plain = Material("plain", 1.0, (0.6, 0.5, 0.3), (0.6, 0.5, 0.3), 0.45, 0.45, 0.3, 0.3, 0.4)
    bricks = Material("bricks", 0.2, (0.7, 0.3, 0.2), (0.6, 0.6, 0.6), 0.3, 0.7, 0.3, 0.3, 0.4)
    materials = np.stack([plain.row(), bricks.row()])
    prims = np.zeros((2, PRIM_SIZE))
    prims[1, PRIM_MATERIAL] = 1
    rng = np.random.default_rng(3)  # the same spots every time
    spots = {
        "plain": (0, rng.uniform(-3.0, 3.0, (1000, 2))),
        "bricks": (1, rng.uniform(-3.0, 3.0, (1000, 2))),
        # bricks 0.4 x 0.2 m, mortar along s = 0, 0.4 and u = 0, 0.2 in the first row
        "brick": (1, rng.uniform((0.05, 0.03), (0.35, 0.17), (1000, 2))),
    }
    out = {}
    for name, (prim, surface) in spots.items():
        args = (prims, materials, np.full(1000, prim), np.zeros(1000, dtype=np.int64), surface)
        albedo, reflectivity, _, _ = surface_properties(*args, gap=gap, without=without)
        out[name] = albedo, reflectivity
    return out


PLAIN_COLOUR = np.array([0.6, 0.5, 0.3])


def test_texture_switches():
    full = _texture_probe(())
    for albedo, reflectivity in full.values():  # both sensors see texture everywhere
        assert albedo[:, 0].std() > 0.002 and reflectivity.std() > 0.002
    # camera texture off: a plain material's albedo is its colour all over the surface, a brick
    # wall's is one colour per brick; the LiDAR's as it was
    off = _texture_probe(("camera-texture",))
    assert_array_equal(off["plain"][0], np.broadcast_to(PLAIN_COLOUR, (1000, 3)))
    assert_array_equal(off["brick"][0], np.broadcast_to(off["brick"][0][0], (1000, 3)))
    for name in full:
        assert_array_equal(off[name][1], full[name][1])
    # LiDAR texture off: a plain material's reflectivity is its own value; the camera as it was
    off = _texture_probe(("lidar-texture",))
    assert_array_equal(off["plain"][1], 0.45)
    assert np.all(off["brick"][1] == off["brick"][1][0])
    for name in full:
        assert_array_equal(off[name][0], full[name][0])
    # materials off too: the luminance of the camera's colour instead of the designed value
    off = _texture_probe(("lidar-texture", "materials"))
    assert_allclose(off["plain"][1], PLAIN_COLOUR @ LUMA, rtol=1e-15)
    # everything off: the LiDAR sees the albedo's luminance (no channel clips here) ...
    everything = ("camera-texture", "lidar-texture", "materials", "elements")
    off = _texture_probe(everything)
    for albedo, reflectivity in off.values():
        assert_allclose(reflectivity, albedo @ LUMA, rtol=1e-14)
    # ... but for the per-element tone, which reaches the LiDAR at half strength otherwise
    albedo, reflectivity = _texture_probe(everything[:3])["bricks"]
    assert np.abs(reflectivity - albedo @ LUMA).max() > 0.01


def test_texture_switches_compose_with_the_modality_gap():
    """At gap 0 the LiDAR already sees the albedo: only the camera texture switch changes it."""
    albedo, reflectivity = _texture_probe((), gap=0.0)["bricks"]
    assert_allclose(reflectivity, albedo @ LUMA, rtol=1e-14)
    for effect in ("lidar-texture", "materials", "elements"):
        assert_array_equal(_texture_probe((effect,), gap=0.0)["bricks"][1], reflectivity)
    _, reflectivity = _texture_probe(("camera-texture",), gap=0.0)["plain"]
    assert_allclose(reflectivity, PLAIN_COLOUR @ LUMA, rtol=1e-15)


def _wall_scene():
    """A grey plaster wall 4 m ahead of the origin, lit by the ambient light only."""
    b = SceneBuilder()
    wall = b.material(Material("plain", 1.0, (0.5,) * 3, (0.5,) * 3, 0.5, 0.5, 0.0, 0.0))
    b.rectangle((4, 0, 0), (0, 1, 0), (0, 0, 1), (20, 20), wall)
    return b.build(lighting=Lighting(ambient=0.5))


def test_optics_off_gives_an_image_without_noise():
    scene = _wall_scene()
    camera = example_camera("pinhole", *SMALL)
    T_world_camera = make_T(np.array([[0, 0, 1.0], [-1, 0, 0], [0, -1, 0]]), np.zeros(3))
    image = render_image(scene, camera, T_world_camera, RenderConfig(exposure=1.0)).image
    assert image.std() > 0.5  # read and shot noise on a flat grey
    config = render_without(RenderConfig(exposure=1.0), ("optics",))
    image = render_image(scene, camera, T_world_camera, config).image
    assert np.all(image == image[0, 0]) and 100 < image[0, 0] < 200


def test_shading_off_is_the_albedo_times_a_constant():
    scene = make_scene(kind="street", seed=2)
    camera = example_camera("pinhole", *SMALL)
    bearings = camera.unproject(camera.pixel_grid())
    directions = bearings @ np.array([[0, 0, 1.0], [-1, 0, 0], [0, -1, 0]]).T
    flat, _, _ = radiance(scene, np.zeros(3), directions, 0.0, shading=False)
    hits = scene.cast(np.zeros(3), directions)
    albedo, _, _, _ = scene.surface_properties(hits, footprint=np.zeros(len(directions)))
    light = scene.lighting.ambient + scene.lighting.sun_irradiance
    h = hits.hit
    assert_array_equal(flat[h], albedo[h] * light)
    shaded, _, _ = radiance(scene, np.zeros(3), directions, 0.0)
    assert not np.allclose(shaded[h], flat[h])
    unshadowed, _, _ = radiance(scene, np.zeros(3), directions, 0.0, shadows=False)
    assert np.all(unshadowed >= shaded) and np.any(unshadowed > shaded)


def _plain_box_room():
    """The box room of :func:`_box_room` in one plain material without texture."""
    b = SceneBuilder()
    m = b.material(Material("plain", 1.0, (0.5,) * 3, (0.5,) * 3, 0.5, 0.5, 0.0, 0.0))
    for center, a, c, size in [
        ((4, 0, 0), (0, 1, 0), (0, 0, 1), (5, 3)),
        ((-3, 0, 0), (0, 1, 0), (0, 0, 1), (5, 3)),
        ((0, 5, 0), (1, 0, 0), (0, 0, 1), (5, 3)),
        ((0, -4, 0), (1, 0, 0), (0, 0, 1), (5, 3)),
        ((0, 0, -1.5), (1, 0, 0), (0, 1, 0), (5, 5)),
        ((0, 0, 2.5), (1, 0, 0), (0, 1, 0), (5, 5)),
    ]:
        b.rectangle(center, a, c, size, m)
    return b.build()


def test_lidar_noise_and_falloff_off():
    scene, planes = _box_room()
    trajectory = make_trajectory(MotionConfig(kind="static"), 0.2)
    lidar = lidar_preset("spinning32", columns=512)
    quiet = lidar_without(lidar, ("lidar-noise",))
    a = simulate_scan(scene, quiet, trajectory, 0.0, np.random.default_rng(1))
    b = simulate_scan(scene, quiet, trajectory, 0.0, np.random.default_rng(2))
    # nothing random is left: other seeds, the same scan; every beam returns, on a wall
    for field in ("points", "intensities", "rings"):
        assert_array_equal(getattr(a, field), getattr(b, field))
    assert len(a) == lidar.points_per_scan
    assert _plane_distance(a.points, planes).max() < 1e-9
    noisy = simulate_scan(scene, lidar, trajectory, 0.0, np.random.default_rng(1))
    assert len(noisy) < len(a) and _plane_distance(noisy.points, planes).max() > 0.01
    # without falloff the intensity is the reflectivity: one value in a room of one material
    plain = _plain_box_room()
    flat = lidar_without(quiet, ("lidar-falloff",))
    c = simulate_scan(plain, flat, trajectory, 0.0, np.random.default_rng(1))
    assert len(c) == len(a) and np.all(c.intensities == 255.0 * 0.5)
    d = simulate_scan(plain, quiet, trajectory, 0.0, np.random.default_rng(1))
    assert d.intensities.std() > 10  # incidence and range
    # with the noise: the reflectivity times the intensity noise
    noisy = lidar_without(lidar, ("lidar-falloff",))
    e = simulate_scan(plain, noisy, trajectory, 0.0, np.random.default_rng(1))
    assert_allclose(np.std(e.intensities / 127.5 - 1.0), lidar.intensity_noise, rtol=0.1)


@pytest.mark.parametrize("noise", [True, False])
def test_motion_off_writes_one_cloud_on_the_true_surfaces(noise):
    """Each point deskewed with the true trajectory lies on the surface its beam hit."""
    without = ("motion",) if noise else ("motion", "lidar-noise")
    seq = generate_sequence(_small("spinning16", seed=3, duration=0.3, without=without))
    assert len(seq.scans) == 3 and seq.motion.kind == "nod"
    (cloud,) = seq.output_scans()
    points, intensities = seq.dense_cloud()
    assert_array_equal(cloud.points, points)
    assert_array_equal(cloud.intensities, intensities)
    assert cloud.stamp == 0.0 and np.all(cloud.times == 0.0)
    assert_array_equal(cloud.rings, np.concatenate([s.rings for s in seq.scans]))
    # cast each point's beam again from where the rig was when it fired
    times = np.concatenate([s.stamp + s.times for s in seq.scans])
    origins = seq.trajectory.poses(times)[:, :3, 3]
    offsets = cloud.points - origins
    distance = np.linalg.norm(offsets, axis=1)
    hits = seq.scene.cast(origins, offsets / distance[:, None])
    assert_array_equal(hits.prim, cloud.prim)
    residual = distance - hits.t
    if noise:
        assert_allclose(residual.std(), seq.lidar.range_noise, rtol=0.1)
    else:
        assert np.abs(residual).max() < 1e-9
    # the sweeps themselves are as simulated: distorted by the motion
    assert not np.allclose(seq.scans[-1].points, seq.scans[-1].points_undistorted)
