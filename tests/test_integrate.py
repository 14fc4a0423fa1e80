"""Dense clouds: voxel maps, deskewing, static and dynamic (continuous-time ICP) integration.

The dynamic tests use a small analytic scene built here (a room with boxes, every surface a
plane), scanned by a spinning LiDAR that moves at constant velocity, for which the pose
interpolation of the method (slerp + lerp) is exact: the ground truth is known to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from numba_regions import parallel_regions
from numpy.testing import assert_allclose
from tolerances import TOL

from nbcalib.errors import InputError
from nbcalib.kernels import ct_icp
from nbcalib.kernels.lie import so3_exp as so3_exp_kernel
from nbcalib.preprocess import integrate as I
from nbcalib.reference import integrate as ref
from nbcalib.transforms import interpolate_pose, make_T, pose_error, so3_exp, transform_points

# ---------------------------------------------------------------------------------------------
# A small analytic scene and a spinning LiDAR moving at constant velocity
# ---------------------------------------------------------------------------------------------

ROOM = (np.array([-9.0, -7.0, -1.5]), np.array([11.0, 6.0, 3.5]))  # interior, LiDAR inside
BOXES = [  # solid boxes (lo, hi)
    (np.array([3.0, 2.0, -1.5]), np.array([4.5, 3.0, 0.5])),
    (np.array([-5.0, -5.5, -1.5]), np.array([-3.5, -3.0, 1.0])),
    (np.array([6.0, -4.0, -1.5]), np.array([7.0, -2.5, 2.0])),
    (np.array([-2.0, 3.5, 0.5]), np.array([0.5, 5.0, 1.5])),
]
SCAN_PERIOD = 0.1
#: constant velocity: world-frame linear velocity (m/s) and angular velocity (rad/s)
VELOCITY = np.array([1.5, 0.4, 0.05])
OMEGA = np.array([0.03, -0.05, 0.5])


def _pose(t: float) -> np.ndarray:
    """T_world_lidar(t) of the constant-velocity motion (slerp + lerp of any two is exact)."""
    return make_T(so3_exp(t * OMEGA), t * VELOCITY)


def _pattern(beams: int = 16, columns: int = 600):
    """Unit directions (LiDAR frame) and times of one sweep: clockwise from behind."""
    elevation = np.radians(np.linspace(-25.0, 20.0, beams))
    column = np.arange(columns)
    azimuth = np.pi - 2.0 * np.pi * column / columns
    az = np.repeat(azimuth, beams)
    el = np.tile(elevation, columns)
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    return d, np.repeat(column * SCAN_PERIOD / columns, beams)


def _cast(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance along each ray to the first surface of the scene."""
    lo, hi = ROOM
    with np.errstate(divide="ignore", invalid="ignore"):
        exit_t = np.where(directions > 0, (hi - origins) / directions, (lo - origins) / directions)
    best = np.nanmin(np.where(exit_t > 0, exit_t, np.inf), axis=1)
    for blo, bhi in BOXES:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (blo - origins) / directions
            t2 = (bhi - origins) / directions
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (near <= far) & (near > 0)
        best = np.where(hit & (near < best), near, best)
    return best


def _scene_distance(points_world: np.ndarray) -> np.ndarray:
    """Unsigned distance from each point to the nearest surface of the scene."""
    lo, hi = ROOM
    distance = np.min(np.abs(np.concatenate([points_world - lo, hi - points_world], axis=1)), 1)
    for blo, bhi in BOXES:
        c, h = 0.5 * (blo + bhi), 0.5 * (bhi - blo)
        q = np.abs(points_world - c) - h
        sdf = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        distance = np.minimum(distance, np.abs(sdf))
    return distance


def _constant_velocity(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R_world_lidar (N, 3, 3) and t_world_lidar (N, 3) at times t (N,): constant velocity."""
    return so3_exp(t[:, None] * OMEGA), t[:, None] * VELOCITY


#: rest for one scan, then constant acceleration (m/s^2) and angular acceleration (rad/s^2)
ACCELERATION = np.array([3.0, 0.5, 0.0])
ANGULAR_ACCELERATION = np.array([0.0, 0.3, 4.0])


def _rest_then_accelerate(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The collection procedure: still during the first scan, then speeding up from rest."""
    moving = np.maximum(t - SCAN_PERIOD, 0.0)[:, None]
    return so3_exp(0.5 * moving**2 * ANGULAR_ACCELERATION), 0.5 * moving**2 * ACCELERATION


def _at_rest(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.broadcast_to(np.eye(3), (t.size, 3, 3)).copy(), np.zeros((t.size, 3))


def _sequence(n_scans: int, *, noise: float = 0.003, seed: int = 0, motion=_constant_velocity):
    """Scans (N, 4) x, y, z, intensity in the LiDAR frame at each point's time, their times and
    the true (T_world_begin, T_world_end) of each scan."""
    rng = np.random.default_rng(seed)
    d_lidar, times = _pattern()
    scans, scan_times, truth = [], [], []
    for k in range(n_scans):
        t0 = k * SCAN_PERIOD
        R, origins = motion(t0 + times)
        d_world = np.einsum("nij,nj->ni", R, d_lidar)
        r = _cast(origins, d_world) + noise * rng.standard_normal(times.size)
        hit_world = origins + r[:, None] * d_world
        intensity = 0.5 + 0.4 * np.sin(3.0 * hit_world[:, 0]) * np.cos(2.0 * hit_world[:, 2])
        scans.append(np.column_stack([r[:, None] * d_lidar, intensity]))
        scan_times.append(times.copy())
        ends = motion(np.array([t0, t0 + times[-1]]))
        truth.append(tuple(make_T(ends[0][j], ends[1][j]) for j in range(2)))
    return scans, scan_times, truth


@pytest.fixture(scope="module")
def sequence():
    return _sequence(6)


@pytest.fixture(scope="module")
def dynamic_cloud(sequence):
    scans, times, _ = sequence
    return I.integrate_dynamic(scans, times)


# ---------------------------------------------------------------------------------------------
# Voxel map: kernel == brute-force reference
# ---------------------------------------------------------------------------------------------


def _nasty_cloud(rng, n=3000):
    """Points on a few planes plus clutter, with exact duplicates and points on voxel faces."""
    plane = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), np.zeros(n)])
    clutter = rng.uniform(-3, 3, (n // 3, 3))
    faces = np.round(rng.uniform(-3, 3, (200, 3)) * 2.0) / 2.0  # exactly on 0.5 m voxel faces
    dupes = plane[:100].copy()
    return np.vstack([plane, clutter, faces, dupes])


@pytest.mark.parametrize("min_spacing", [0.0, 0.05])
def test_voxelmap_insert_matches_reference(rng, min_spacing):
    points = _nasty_cloud(rng)
    kernel_map = I.VoxelMap(0.5, max_points_per_voxel=7, min_spacing=min_spacing, capacity=16)
    reference_map = ref.VoxelMapReference(0.5, 7, min_spacing)
    for chunk in np.array_split(points, 3):  # several insertions, with growth of the table
        assert kernel_map.insert(chunk) == reference_map.insert(chunk)
    kernel_points, kernel_flat = kernel_map.points()
    reference_points, reference_flat = reference_map.points()
    assert np.array_equal(kernel_flat, reference_flat)
    assert np.array_equal(kernel_points, reference_points)


@pytest.mark.parametrize(("k", "max_distance"), [(1, 0.5), (5, 0.5), (8, 0.2)])
def test_voxelmap_knn_is_exact(rng, k, max_distance):
    """27-voxel search with max_distance <= voxel == brute force over all stored points."""
    points = _nasty_cloud(rng)
    vmap = I.VoxelMap(0.5, max_points_per_voxel=9, min_spacing=0.0)
    vmap.insert(points)
    stored, flat = vmap.points()
    queries = np.vstack([rng.uniform(-3.5, 3.5, (300, 3)), stored[:50], points[-100:-90]])
    idx, d2 = vmap.knn(queries, k, max_distance)
    idx_ref, d2_ref = ref.knn_bruteforce(stored, flat, queries, k, max_distance)
    assert np.array_equal(idx, idx_ref)
    assert np.array_equal(d2, d2_ref)


def test_voxelmap_remove_far_keeps_near_voxels(rng):
    vmap = I.VoxelMap(1.0, max_points_per_voxel=4)
    points = rng.uniform(-20, 20, (4000, 3))
    vmap.insert(points)
    before, _ = vmap.points()
    vmap.remove_far(np.zeros(3), 10.0)
    after, _ = vmap.points()
    assert 0 < len(after) < len(before)
    assert np.linalg.norm(after, axis=1).max() < 10.0 + np.sqrt(3)  # voxel centre within 10 m
    # what stayed is still found: a query at a kept point finds it at distance 0
    idx, d2 = vmap.knn(after[:20], 1, 1.0)
    assert np.all(d2[:, 0] == 0.0)
    assert np.array_equal(vmap.point(idx[:, 0]), after[:20])


def test_voxel_extent_is_checked():
    vmap = I.VoxelMap(0.002)
    with pytest.raises(ValueError, match="voxel grid covers"):
        vmap.insert(np.array([[3000.0, 0.0, 0.0]]))


# ---------------------------------------------------------------------------------------------
# Downsampling and de-duplication: kernel == reference
# ---------------------------------------------------------------------------------------------


def test_voxel_downsample_matches_reference(rng):
    points = _nasty_cloud(rng)
    assert np.array_equal(I.voxel_downsample(points, 0.3), ref.voxel_first_indices(points, 0.3))


def test_stratified_downsample(rng):
    points = _nasty_cloud(rng)
    idx = I.stratified_downsample(points, 0.5, 1000)
    assert np.all(np.diff(idx) > 0)
    n_voxels = len(ref.voxel_first_indices(points, 0.5))
    assert 1000 <= len(idx) < 1000 + n_voxels
    assert np.array_equal(idx, I.stratified_downsample(points, 0.5, 1000))  # deterministic
    assert np.array_equal(I.stratified_downsample(points, 0.5, 10**6), np.arange(len(points)))
    few = I.stratified_downsample(points, 0.01, 500)  # more voxels than target: thinned
    assert len(few) == 500


@pytest.mark.parametrize("rule", ["mean", "last"])
def test_voxel_deduplicate_matches_reference(rng, rule):
    points = np.vstack([_nasty_cloud(rng), _nasty_cloud(rng)[:500] + 1e-4])
    intensity = rng.uniform(0, 255, len(points))
    got = I.voxel_deduplicate(points, intensity, voxel_size=0.05, rule=rule)
    want = ref.voxel_deduplicate(points, intensity, 0.05, rule)
    if rule == "last":  # copies of input values: exact
        assert np.array_equal(got[0], want[0])
        assert np.array_equal(got[1], want[1])
    else:  # sums in the same order, one division each
        assert_allclose(got[0], want[0], **TOL["kernel_vs_reference"])
        assert_allclose(got[1], want[1], **TOL["kernel_vs_reference"])
    # one point per voxel, in order of first appearance
    keys = np.floor(got[0] / 0.05)
    assert len(np.unique(keys, axis=0)) == len(keys)


# ---------------------------------------------------------------------------------------------
# Deskewing and the continuous-time ICP kernels: kernel == reference
# ---------------------------------------------------------------------------------------------


def test_deskew_matches_reference_and_parallel_is_serial(rng):
    points = rng.uniform(-30, 30, (2000, 3))
    s = rng.uniform(0, 1, 2000)
    s[:3] = [0.0, 1.0, 0.5]
    T_b = make_T(so3_exp(np.array([0.1, -0.2, 0.3])), np.array([5.0, -2.0, 1.0]))
    T_e = make_T(so3_exp(np.array([0.12, -0.15, 0.41])), np.array([5.4, -1.9, 1.1]))
    got = I.deskew(points, s, T_b, T_e)
    assert_allclose(got, ref.deskew(points, s, T_b, T_e), **TOL["deskew_vs_reference"])
    assert np.array_equal(got, I.deskew(points, s, T_b, T_e, parallel=True))
    assert_allclose(got[0], transform_points(T_b, points[0]), **TOL["transform"])
    assert_allclose(got[1], transform_points(T_e, points[1]), **TOL["transform"])


def test_associate_and_normal_equations_match_reference(rng):
    # a map of a box corner region (three planes) plus clutter; a perturbed source
    n = 1500
    walls = np.vstack(
        [
            np.column_stack([rng.uniform(0, 4, n), rng.uniform(0, 4, n), np.zeros(n)]),
            np.column_stack([np.zeros(n), rng.uniform(0, 4, n), rng.uniform(0, 4, n)]),
            np.column_stack([rng.uniform(0, 4, n), np.full(n, 4.0), rng.uniform(0, 4, n)]),
        ]
    )
    walls += 0.003 * rng.standard_normal(walls.shape)
    vmap = I.VoxelMap(1.0, max_points_per_voxel=30, min_spacing=0.05)
    vmap.insert(walls)
    reference_map = ref.VoxelMapReference(1.0, 30, 0.05)
    reference_map.insert(walls)
    source = walls[rng.choice(len(walls), 400, replace=False)] + rng.normal(0, 0.01, (400, 3))
    s = rng.uniform(0, 1, 400)
    T_b = make_T(so3_exp(np.array([0.0, 0.01, 0.02])), np.array([0.02, -0.01, 0.0]))
    T_e = make_T(so3_exp(np.array([0.01, 0.0, 0.03])), np.array([0.05, 0.0, 0.01]))
    R_b, t_b, t_e = T_b[:3, :3].copy(), T_b[:3, 3].copy(), T_e[:3, 3].copy()
    phi = I._relative_rotation_vector(R_b, T_e[:3, :3])
    planes = np.empty((400, ct_icp.PLANE_SIZE))
    args = (source, s, R_b, t_b, t_e, phi, vmap.table, vmap.counts, vmap.store, 1.0, 10, 0.5, 5)
    ct_icp._associate(*args, 0.03, planes)
    want = ref.associate(source, s, T_b, T_e, reference_map, 10, 0.5, 5, 0.03)
    got = planes.copy()
    flip = np.sign(got[np.arange(400), np.argmax(np.abs(got[:, :3]), axis=1)])
    flip[flip == 0] = 1.0
    got[:, :4] *= flip[:, None]
    assert np.array_equal(got[:, 4] > 0, want[:, 4] > 0)
    assert (want[:, 4] > 0).sum() > 300
    assert_allclose(got, want, **TOL["plane_fit_vs_eigh"])  # closed-form vs eigh eigenvectors

    planes_parallel = np.empty_like(planes)
    ct_icp._associate_parallel(*args, 0.03, planes_parallel)
    assert np.array_equal(planes, planes_parallel)

    H, g, cost, used = ct_icp._normal_equations(source, s, R_b, t_b, t_e, phi, planes, 0.05)
    H_ref, g_ref, cost_ref, used_ref = ref.normal_equations(source, s, T_b, T_e, want, 0.05)
    assert used == used_ref
    assert_allclose(H, H_ref, **TOL["plane_fit_vs_eigh"])
    assert_allclose(g, g_ref, **TOL["plane_fit_vs_eigh"])
    assert_allclose(cost, cost_ref, **TOL["plane_fit_vs_eigh"])
    Hp, gp, cp, up = ct_icp._normal_equations_parallel(source, s, R_b, t_b, t_e, phi, planes, 0.05)
    assert np.array_equal(H, Hp) and np.array_equal(g, gp) and cost == cp and used == up
    # one parallel region per call each (tests/numba_regions.py says why)
    assert parallel_regions(ct_icp._associate_parallel, *args, 0.03, planes_parallel) == 1
    normal_args = (source, s, R_b, t_b, t_e, phi, planes, 0.05)
    assert parallel_regions(ct_icp._normal_equations_parallel, *normal_args) == 1


def test_normal_equations_jacobian_vs_finite_differences(rng):
    """The kernel's 12 x 12 system is J^T W J, J = d(point-to-plane residual)/d increments."""
    points = rng.uniform(-5, 5, (50, 3))
    s = rng.uniform(0, 1, 50)
    planes = np.zeros((50, ct_icp.PLANE_SIZE))
    normals = rng.normal(size=(50, 3))
    planes[:, :3] = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    planes[:, 3] = rng.normal(size=50)
    planes[:, 4] = 1.0
    T_b = make_T(so3_exp(np.array([0.1, 0.2, -0.1])), np.array([1.0, 2.0, 0.5]))
    T_e = make_T(so3_exp(np.array([0.11, 0.21, -0.08])), np.array([1.1, 2.05, 0.5]))

    def residuals(delta):
        Tb = I._apply_increment(T_b, delta[:6], so3_exp_kernel)
        Te = I._apply_increment(T_e, delta[6:], so3_exp_kernel)
        world = ref.deskew(points, s, Tb, Te)
        return np.einsum("ij,ij->i", world, planes[:, :3]) - planes[:, 3]

    h = 1e-6
    J = np.stack(
        [(residuals(h * e) - residuals(-h * e)) / (2 * h) for e in np.eye(12)], axis=1
    )  # (50, 12)
    r = residuals(np.zeros(12))
    w = (1e6 / (1e6 + r * r)) ** 2  # robust scale 1000 m: weights ~ 1
    R_b, t_b, t_e = T_b[:3, :3].copy(), T_b[:3, 3].copy(), T_e[:3, 3].copy()
    phi = I._relative_rotation_vector(R_b, T_e[:3, :3])
    H, g, _, _ = ct_icp._normal_equations(points, s, R_b, t_b, t_e, phi, planes, 1000.0)
    # translation columns exactly; rotation columns to first order in the intra-scan rotation
    # (phi ~ 0.04 rad here): the error is a few percent of the largest entry, no more
    g_fd, H_fd = (w * r) @ J, (J * w[:, None]).T @ J
    assert_allclose(
        g[[0, 1, 2, 6, 7, 8]], g_fd[[0, 1, 2, 6, 7, 8]], **TOL["jacobian_vs_finite_diff"]
    )
    assert np.abs(g - g_fd).max() < 0.02 * np.abs(g_fd).max()
    assert np.abs(H - H_fd).max() < 0.02 * np.abs(H_fd).max()


# ---------------------------------------------------------------------------------------------
# Per-point times
# ---------------------------------------------------------------------------------------------


def test_synthesize_times_from_azimuth():
    az = np.radians([180.0 - 1e-9, 90.0, 0.0, -90.0, -179.0])
    points = np.column_stack([np.cos(az), np.sin(az), np.zeros(5)]) * 10.0
    t = I.synthesize_times_from_azimuth(points, 10.0)  # clockwise from behind
    assert_allclose(t, [0.0, 0.025, 0.05, 0.075, 0.1 * 359 / 360], atol=1e-9)
    t_ccw = I.synthesize_times_from_azimuth(points, 10.0, clockwise=False)
    assert_allclose(t_ccw[1:4], [0.075, 0.05, 0.025], atol=1e-9)
    assert np.all((t >= 0) & (t < 0.1))
    d, times = _pattern()
    assert_allclose(I.synthesize_times_from_azimuth(d, 1 / SCAN_PERIOD), times, atol=1e-9)


@pytest.mark.parametrize("with_times", [False, True])
@pytest.mark.parametrize("clockwise", [True, False])
def test_select_points_matches_reference(rng, with_times, clockwise):
    points = rng.uniform(-20, 20, (3000, 3))
    points[:100] *= 0.01  # within min_distance
    points[100:110, 1] = np.nan
    points[110, 2] = np.inf
    intensity = rng.uniform(0, 1, 3000)
    intensity[120] = np.nan
    times = rng.uniform(5.0, 5.1, 3000) if with_times else None
    if with_times:
        times[130] = np.nan
    got = ct_icp._select_points(
        points,
        intensity,
        times if with_times else np.zeros(0),
        with_times,
        10.0,
        clockwise,
        np.radians(170.0),
        1.0,
        True,
    )
    want = ref.select_points(points, intensity, times, 10.0, clockwise, 170.0, 1.0)
    assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
    assert got[3] == want[3] == 3000 - 12 - (1 if with_times else 0)
    assert_allclose(got[2], want[2], **TOL["kernel_vs_reference"])
    assert_allclose(got[4], want[4], **TOL["kernel_vs_reference"])


def test_normalized_scan_times():
    s, duration = I.normalized_scan_times([5.0, 5.05, 5.1])
    assert_allclose(s, [0.0, 0.5, 1.0])
    assert duration == pytest.approx(0.1)
    s, duration = I.normalized_scan_times([2.0, 2.0])
    assert np.array_equal(s, [0.0, 0.0]) and duration == 0.0


# ---------------------------------------------------------------------------------------------
# Static integration
# ---------------------------------------------------------------------------------------------


def test_integrate_static_dedups_and_filters_range(rng):
    scan = np.column_stack([rng.uniform(-5, 5, (1000, 3)), rng.uniform(0, 1, 1000)])
    scan[:10, :3] *= 0.01  # within min_distance
    scans = [scan, scan + np.array([1e-4, 0, 0, 0]), scan[:300]]
    cloud = I.integrate_static(scans, voxel_size=0.01, min_distance=1.0, dedup="last")
    points = np.vstack([s[:, :3] for s in scans])
    intensity = np.concatenate([s[:, 3] for s in scans])
    near = np.linalg.norm(points, axis=1) < 1.0
    want = ref.voxel_deduplicate(points[~near], intensity[~near], 0.01, "last")
    assert np.array_equal(cloud.points, want[0]) and np.array_equal(cloud.intensity, want[1])
    assert cloud.T_first_scanbegin.shape == (3, 4, 4)
    assert np.array_equal(cloud.T_first_scanend[1], np.eye(4))
    assert cloud.stats["points_used"].tolist() == [int((~near[:1000]).sum())] * 2 + [
        int((~near[:300]).sum())
    ]


def test_integrate_static_accepts_pointcloud_objects(rng):
    from nbcalib.io.pointcloud import PointCloud

    pts = rng.uniform(2, 5, (100, 3))
    cloud = I.integrate_static([PointCloud(points=pts, intensity=np.arange(100.0))])
    assert len(cloud) == 100
    assert_allclose(cloud.intensity, np.arange(100.0))
    no_intensity = I.integrate_static([pts])
    assert np.all(no_intensity.intensity == 0.0)


# ---------------------------------------------------------------------------------------------
# Dynamic integration on the analytic scene
# ---------------------------------------------------------------------------------------------


def test_dynamic_recovers_constant_velocity_motion(sequence, dynamic_cloud):
    _, _, truth = sequence
    T_b_true = np.stack([b for b, _ in truth])
    T_e_true = np.stack([e for _, e in truth])
    tb, rb = pose_error(dynamic_cloud.T_first_scanbegin, T_b_true)
    te, re = pose_error(dynamic_cloud.T_first_scanend, T_e_true)
    assert np.array_equal(dynamic_cloud.T_first_scanbegin[0], np.eye(4))
    assert rb.max() < 0.1 and re.max() < 0.1, (rb, re)  # degrees
    assert tb.max() < 0.01 and te.max() < 0.01, (tb, te)  # metres
    assert dynamic_cloud.stats["registered"].all()


def test_first_scan_at_rest_is_not_deskewed_with_the_second_scans_motion():
    """Still during the first scan, then accelerating: the rigid bootstrap of the first scan's
    motion (constant velocity) would give it part of the second scan's motion and distort the
    map; the second scan's own registration says it begins at rest."""
    scans, times, truth = _sequence(5, motion=_rest_then_accelerate)
    cloud = I.integrate_dynamic(scans, times)
    assert np.array_equal(cloud.T_first_scanend[0], np.eye(4))
    T_e_true = np.stack([e for _, e in truth])
    te, re = pose_error(cloud.T_first_scanend, T_e_true)
    # slerp + lerp cannot follow an acceleration within a scan: up to ~0.29 degree here (alpha
    # T^2 / 8); the constant-velocity bootstrap gave 7 mm / 0.17 degree at the first scan's end
    # and 0.43 degree at the others
    assert te.max() < 0.012 and re.max() < 0.33, (te, re)  # metres, degrees


def test_moving_first_scan_is_deskewed(sequence, dynamic_cloud):
    """At constant velocity from the start, the first scan's end pose is the motion over it."""
    _, _, truth = sequence
    te, re = pose_error(dynamic_cloud.T_first_scanend[:1], truth[0][1][None])
    assert np.linalg.norm(truth[0][1][:3, 3]) > 0.1  # it did move
    assert te[0] < 0.005 and re[0] < 0.05, (te, re)


def test_narrow_kernel_removes_the_bias_at_rest():
    """A LiDAR at rest, 3 mm range noise: with the kernel narrowed to the noise the poses stay
    closer to rest than with a fixed 10 cm kernel, which lets points matched to the wrong
    surface (box edges) pull them."""
    scans, times, _ = _sequence(6, motion=_at_rest)

    def worst(config):
        cloud = I.integrate_dynamic(scans, times, config=config)
        eye = np.broadcast_to(np.eye(4), cloud.T_first_scanend.shape)
        tb, rb = pose_error(cloud.T_first_scanbegin, eye)
        te, re = pose_error(cloud.T_first_scanend, eye)
        return max(tb.max(), te.max()), max(rb.max(), re.max())

    narrow_t, narrow_r = worst(I.DynamicIntegrationConfig())
    _, wide_r = worst(I.DynamicIntegrationConfig(robust_sigmas=0.0))
    # measured: narrow 1.8 mm / 0.015 degree, wide 1.8 mm / 0.020 degree (the worst pose is a
    # scan's end, whose translation within the scan is the weakly observed part)
    assert narrow_t < 0.003 and narrow_r < 0.02, (narrow_t, narrow_r)
    assert narrow_r < wide_r, (narrow_r, wide_r)


def test_deskewed_cloud_is_sharper_than_raw(sequence, dynamic_cloud):
    """RMS distance to the known planes: deskewed accumulation < rigid per-scan accumulation."""
    scans, _, _ = sequence
    deskewed = np.sqrt(np.mean(_scene_distance(dynamic_cloud.points) ** 2))
    raw = []
    for scan, T_b, T_e in zip(
        scans, dynamic_cloud.T_first_scanbegin, dynamic_cloud.T_first_scanend
    ):
        raw.append(transform_points(interpolate_pose(T_b, T_e, 0.5), scan[:, :3]))
    raw_rms = np.sqrt(np.mean(_scene_distance(np.vstack(raw)) ** 2))
    assert deskewed < 0.01  # range noise is 3 mm
    assert deskewed < 0.5 * raw_rms, (deskewed, raw_rms)


def test_dynamic_is_deterministic(sequence, dynamic_cloud):
    scans, times, _ = sequence
    again = I.integrate_dynamic(
        scans[:4],
        times[:4],
        config=I.DynamicIntegrationConfig(background_accumulation=False, threads=1, parallel=True),
    )
    first = I.integrate_dynamic(scans[:4], times[:4])
    assert np.array_equal(first.points, again.points)
    assert np.array_equal(first.intensity, again.intensity)
    assert np.array_equal(first.T_first_scanend, again.T_first_scanend)
    assert np.array_equal(first.T_first_scanend, dynamic_cloud.T_first_scanend[:4])


def test_dynamic_uses_scan_times_and_reports_progress(sequence):
    scans, times, _ = sequence
    calls = []
    cloud = I.integrate_dynamic(
        [s[:, :3] for s in scans[:3]],
        times[:3],
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert np.all(cloud.intensity == 0.0)
    # without times, they are synthesised from the azimuth (the same here)
    no_times = I.integrate_dynamic(
        [s[:, :3] for s in scans[:3]],
        config=I.DynamicIntegrationConfig(frame_rate=1 / SCAN_PERIOD),
    )
    assert_allclose(no_times.T_first_scanend, cloud.T_first_scanend, atol=1e-6)


def test_dynamic_single_scan_and_empty_scans(sequence):
    scans, times, _ = sequence
    empty = np.zeros((0, 4))
    cloud = I.integrate_dynamic([empty, scans[0], empty], [np.zeros(0), times[0], np.zeros(0)])
    assert cloud.stats["registered"].tolist() == [False, True, False]
    assert cloud.stats["points_used"][1] > 0
    assert np.array_equal(cloud.T_first_scanend[1], np.eye(4))
    single = I.integrate_static([scans[0]], voxel_size=0.002)
    assert len(cloud) == len(single)


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


def test_bad_input_raises_clear_errors(sequence):
    scans, times, _ = sequence
    nan_scan = np.full((50, 4), np.nan)
    with pytest.raises(InputError, match="no scans"):
        I.integrate_static([])
    with pytest.raises(InputError, match="no scans"):
        I.integrate_dynamic([])
    with pytest.raises(InputError, match="no finite point"):
        I.integrate_static([nan_scan, np.zeros((0, 3))])
    with pytest.raises(InputError, match="no finite point"):
        I.integrate_dynamic([nan_scan])
    with pytest.raises(ValueError, match="times has 1 entries for 2 scans"):
        I.integrate_dynamic(scans[:2], times[:1])
    with pytest.raises(ValueError, match=r"scan 1: .* point times for"):
        I.integrate_dynamic(scans[:2], [times[0], times[1][:-1]])
    with pytest.raises(ValueError, match=r"shape \(N, 3\) or \(N, 4\)"):
        I.integrate_static([np.zeros((5, 2))])
    with pytest.raises(ValueError, match="dedup"):
        I.integrate_static([scans[0]], dedup="median")
    with pytest.raises(ValueError, match="max_correspondence_distance"):
        I.DynamicIntegrationConfig(max_correspondence_distance=2.0)
    with pytest.raises(ValueError, match="frame_rate"):
        I.DynamicIntegrationConfig(frame_rate=0.0)
    with pytest.raises(ValueError, match="robust_sigmas"):
        I.DynamicIntegrationConfig(robust_sigmas=-1.0)
    with pytest.raises(ValueError, match="frame_rate"):
        I.synthesize_times_from_azimuth(np.ones((3, 3)), -1.0)


# ---------------------------------------------------------------------------------------------
# Real data: the KITTI frames drive forward
# ---------------------------------------------------------------------------------------------


@pytest.mark.realdata
def test_kitti_frames_move_forward(real_data):
    folder = real_data / "kitti_raw_2011_09_26"
    scans = [
        np.fromfile(folder / f"{k:010d}" / "velodyne.bin", np.float32).reshape(-1, 4)
        for k in range(4)
    ]
    cloud = I.integrate_dynamic(scans)
    step = np.linalg.norm(np.diff(cloud.T_first_scanend[:, :3, 3], axis=0), axis=1)
    intra = np.linalg.norm(
        cloud.T_first_scanend[:, :3, 3] - cloud.T_first_scanbegin[:, :3, 3], axis=1
    )
    # the car drives at ~2.2 m/s (kiss-icp agrees, docs/BENCHMARKS.md); the motion within a
    # scan matches the motion between scans
    assert np.all((step > 0.15) & (step < 0.3)), step
    assert_allclose(intra, 0.22, atol=0.05)
    assert cloud.T_first_scanend[-1, 0, 3] > 0.6  # forward is +x
