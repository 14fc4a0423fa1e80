"""The trust region of fine registration: measure, projection, penalised cost, chart bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest

import nbcalib.registration.trust as trust
from nbcalib.registration.optimize import minimize_lbfgs, minimize_nelder_mead
from nbcalib.registration.trust import TrustRegion
from nbcalib.transforms import invert_T, pose_error, se3_exp, so3_log


def _region(seed: int = 0, translation: float = 0.1, rotation_deg: float = 3.0):
    rng = np.random.default_rng(seed)
    return TrustRegion(se3_exp(rng.normal(size=6) * 0.3), translation, rotation_deg), rng


def _target_cost(rng):
    """A smooth cost of the camera centre and rotation, minimal at a pose, with its gradient."""
    a = rng.normal(size=3)
    R_b = se3_exp(np.r_[0.0, 0.0, 0.0, rng.normal(size=3) * 0.2])[:3, :3]

    def cost_and_grad(T):
        R, t = T[:3, :3], T[:3, 3]
        c, phi = -R.T @ t - a, so3_log(R @ R_b.T)
        # left perturbation: the centre moves by -R^T v, phi by J_l(phi)^-1 omega
        return float(c @ c + phi @ phi), np.r_[-2.0 * R @ c, 2.0 * phi]

    T_best = np.eye(4)
    T_best[:3, :3] = R_b
    T_best[:3, 3] = -R_b @ a
    return cost_and_grad, T_best


def _numeric_grad(f, T, h=1e-6):
    g = np.zeros(6)
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        g[i] = (f(se3_exp(d) @ T) - f(se3_exp(-d) @ T)) / (2 * h)
    return g


def test_distances_are_pose_error_of_the_inverses():
    region, rng = _region()
    T = se3_exp(rng.normal(size=6) * 0.1) @ region.T_init
    assert region.distances(T) == pose_error(invert_T(T), invert_T(region.T_init))
    assert region.distances(region.T_init) == (0.0, 0.0)


def test_projection_lands_on_the_edge_and_keeps_what_is_inside():
    region, rng = _region()
    inside = se3_exp(np.r_[0.01, 0, 0, 0, 0.01, 0]) @ region.T_init
    np.testing.assert_array_equal(region.project(inside), inside)
    for _ in range(20):
        T = se3_exp(rng.normal(size=6) * np.r_[0.2, 0.2, 0.2, 0.1, 0.1, 0.1]) @ region.T_init
        P = region.project(T)
        dt, dr = region.distances(T)
        pt, pr = region.distances(P)
        assert region.contains(P)
        assert pt == pytest.approx(min(dt, 0.1), rel=1e-9)
        assert pr == pytest.approx(min(dr, 3.0), rel=1e-9)
        assert region.on_boundary(P) == (dt >= 0.1 * 0.99 or dr >= 3.0 * 0.99)
        # the projection moves the centre radially and the rotation along its geodesic
        c, c_p, c0 = (-X[:3, :3].T @ X[:3, 3] for X in (T, P, region.T_init))
        np.testing.assert_allclose(np.cross(c - c0, c_p - c0), 0.0, atol=1e-12)


@pytest.mark.parametrize("penalty", [True, False])
def test_penalised_gradient_is_the_derivative_of_the_penalised_value(monkeypatch, penalty):
    region, rng = _region(1)
    if not penalty:  # the chain rule through the projection alone
        monkeypatch.setattr(trust, "PENALTY_PER_METRE", 0.0)
        monkeypatch.setattr(trust, "PENALTY_PER_RADIAN", 0.0)
    cost_and_grad, _ = _target_cost(rng)
    value_and_grad = region.penalised_value_and_grad(cost_and_grad)
    value = region.penalised_value(lambda T: cost_and_grad(T)[0])
    for _ in range(8):
        T = se3_exp(rng.normal(size=6) * np.r_[0.2, 0.2, 0.2, 0.1, 0.1, 0.1]) @ region.T_init
        v, g = value_and_grad(T)
        assert v == value(T)
        scale = max(1.0, float(np.linalg.norm(g)))
        np.testing.assert_allclose(_numeric_grad(value, T), g, atol=1e-6 * scale)


def test_inside_the_region_the_cost_passes_through_untouched():
    region, rng = _region(2)
    cost_and_grad, _ = _target_cost(rng)
    T = se3_exp(np.r_[0.01, -0.02, 0.0, 0.01, 0.0, -0.01]) @ region.T_init
    v, g = region.penalised_value_and_grad(cost_and_grad)(T)
    v0, g0 = cost_and_grad(T)
    assert v == v0 and np.array_equal(g, g0)
    assert region.penalised_value(lambda X: cost_and_grad(X)[0])(T) == v0
    # outside, the penalised cost is above the cost at the projection
    far = se3_exp(np.r_[0.3, 0, 0, 0, 0, 0.2]) @ region.T_init
    assert (
        region.penalised_value(lambda X: cost_and_grad(X)[0])(far)
        > cost_and_grad(region.project(far))[0]
    )


def test_chart_bounds_hold_every_pose_of_the_region_and_keep_a_smaller_box():
    region, rng = _region(3, translation=0.03, rotation_deg=0.5)
    T0 = se3_exp(np.r_[0.01, 0.0, 0.005, 0.0, 0.003, 0.0]) @ region.T_init
    t_bound, r_bound = region.chart_bounds(T0, 0.2, math.radians(2.0))
    assert t_bound < 0.2 and r_bound < math.radians(2.0)
    # every sampled chart point inside the region lies within the shrunk box
    deltas = rng.uniform(-1, 1, size=(20000, 6)) * np.r_[[0.2] * 3, [math.radians(2.0)] * 3]
    deltas *= rng.uniform(0, 1, size=(20000, 1)) ** 3  # many near the centre
    kept = [d for d in deltas if region.contains(se3_exp(d) @ T0)]
    assert len(kept) > 100
    kept = np.abs(kept)
    assert kept[:, :3].max() <= t_bound and kept[:, 3:].max() <= r_bound
    # the default region never shrinks the default box
    wide = TrustRegion(region.T_init, 0.5, 5.0)
    assert wide.chart_bounds(T0, 0.2, math.radians(2.0)) == (0.2, math.radians(2.0))


@pytest.mark.parametrize("method", ["lbfgs", "nelder_mead"])
def test_inner_optimisers_return_only_poses_in_the_region(method):
    region, rng = _region(4, translation=0.05, rotation_deg=1.0)
    cost_and_grad, T_best = _target_cost(rng)
    assert not region.contains(T_best)  # the minimum lies outside
    T0 = region.T_init
    if method == "lbfgs":
        result = minimize_lbfgs(
            cost_and_grad, T0, max_translation=0.2, max_iterations=200, trust_region=region
        )
    else:
        result = minimize_nelder_mead(
            lambda T: cost_and_grad(T)[0],
            T0,
            init_step=1e-2,
            max_translation=0.2,
            max_evaluations=3000,
            trust_region=region,
        )
    assert region.contains(result.T_camera_lidar) and region.on_boundary(result.T_camera_lidar)
    assert cost_and_grad(result.T_camera_lidar)[0] < cost_and_grad(T0)[0]
    if method == "nelder_mead":  # (L-BFGS-B's value after an abnormal stop is the last trial's)
        assert result.value == pytest.approx(cost_and_grad(result.T_camera_lidar)[0])
    # without the region the same optimiser leaves it
    free = minimize_lbfgs(cost_and_grad, T0, max_translation=0.2, max_iterations=200)
    assert not region.contains(free.T_camera_lidar)


def test_a_region_refuses_bad_sizes():
    with pytest.raises(ValueError, match="trust region"):
        TrustRegion(np.eye(4), -0.1, 5.0)
    with pytest.raises(ValueError, match="trust region"):
        TrustRegion(np.eye(4), 0.1, 180.0)


def test_a_pose_found_outside_is_projected_and_its_cost_taken_there():
    from nbcalib.registration.optimize import InnerResult, _in_region

    region, rng = _region(5)
    cost_and_grad, _ = _target_cost(rng)
    far = se3_exp(np.r_[0.3, 0, 0, 0, 0, 0.2]) @ region.T_init
    found = InnerResult(far, -1.0, 3, 10, True, "converged")
    result = _in_region(found, region, lambda T: cost_and_grad(T)[0])
    assert region.contains(result.T_camera_lidar) and region.on_boundary(result.T_camera_lidar)
    assert result.value == cost_and_grad(result.T_camera_lidar)[0]
    assert result.evaluations == 11 and "projected onto the trust region" in result.message
