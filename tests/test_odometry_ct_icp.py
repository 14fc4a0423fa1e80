"""Deskewing and the continuous-time ICP kernels: kernel == reference, Jacobian vs differences."""

from __future__ import annotations

import numpy as np
from numba_regions import parallel_regions
from numpy.testing import assert_allclose
from tolerances import TOL

from nbcalib.kernels import ct_icp
from nbcalib.kernels.lie import so3_exp as so3_exp_kernel
from nbcalib.odometry.ct_icp import _apply_increment
from nbcalib.odometry.deskew import _relative_rotation_vector, deskew
from nbcalib.odometry.voxelmap import VoxelMap
from nbcalib.reference import integrate as ref
from nbcalib.transforms import make_T, so3_exp, transform_points

# ---------------------------------------------------------------------------------------------
# Deskewing and the continuous-time ICP kernels: kernel == reference
# ---------------------------------------------------------------------------------------------


def test_deskew_matches_reference_and_parallel_is_serial(rng):
    points = rng.uniform(-30, 30, (2000, 3))
    s = rng.uniform(0, 1, 2000)
    s[:3] = [0.0, 1.0, 0.5]
    T_b = make_T(so3_exp(np.array([0.1, -0.2, 0.3])), np.array([5.0, -2.0, 1.0]))
    T_e = make_T(so3_exp(np.array([0.12, -0.15, 0.41])), np.array([5.4, -1.9, 1.1]))
    got = deskew(points, s, T_b, T_e)
    assert_allclose(got, ref.deskew(points, s, T_b, T_e), **TOL["deskew_vs_reference"])
    assert np.array_equal(got, deskew(points, s, T_b, T_e, parallel=True))
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
    vmap = VoxelMap(1.0, max_points_per_voxel=30, min_spacing=0.05)
    vmap.insert(walls)
    reference_map = ref.VoxelMapReference(1.0, 30, 0.05)
    reference_map.insert(walls)
    source = walls[rng.choice(len(walls), 400, replace=False)] + rng.normal(0, 0.01, (400, 3))
    s = rng.uniform(0, 1, 400)
    T_b = make_T(so3_exp(np.array([0.0, 0.01, 0.02])), np.array([0.02, -0.01, 0.0]))
    T_e = make_T(so3_exp(np.array([0.01, 0.0, 0.03])), np.array([0.05, 0.0, 0.01]))
    R_b, t_b, t_e = T_b[:3, :3].copy(), T_b[:3, 3].copy(), T_e[:3, 3].copy()
    phi = _relative_rotation_vector(R_b, T_e[:3, :3])
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
        Tb = _apply_increment(T_b, delta[:6], so3_exp_kernel)
        Te = _apply_increment(T_e, delta[6:], so3_exp_kernel)
        world = ref.deskew(points, s, Tb, Te)
        return np.einsum("ij,ij->i", world, planes[:, :3]) - planes[:, 3]

    h = 1e-6
    J = np.stack(
        [(residuals(h * e) - residuals(-h * e)) / (2 * h) for e in np.eye(12)], axis=1
    )  # (50, 12)
    r = residuals(np.zeros(12))
    w = (1e6 / (1e6 + r * r)) ** 2  # robust scale 1000 m: weights ~ 1
    R_b, t_b, t_e = T_b[:3, :3].copy(), T_b[:3, 3].copy(), T_e[:3, 3].copy()
    phi = _relative_rotation_vector(R_b, T_e[:3, :3])
    H, g, _, _ = ct_icp._normal_equations(points, s, R_b, t_b, t_e, phi, planes, 1000.0)
    # translation columns exactly; rotation columns to first order in the intra-scan rotation
    # (phi ~ 0.04 rad here): the error is a few percent of the largest entry, no more
    g_fd, H_fd = (w * r) @ J, (J * w[:, None]).T @ J
    assert_allclose(
        g[[0, 1, 2, 6, 7, 8]], g_fd[[0, 1, 2, 6, 7, 8]], **TOL["jacobian_vs_finite_diff"]
    )
    assert np.abs(g - g_fd).max() < 0.02 * np.abs(g_fd).max()
    assert np.abs(H - H_fd).max() < 0.02 * np.abs(H_fd).max()
