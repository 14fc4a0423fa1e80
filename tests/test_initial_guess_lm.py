"""Robust LM on the reprojection error: Jacobians, convergence, invalid points."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.initial_guess.lm import (
    cauchy_loss,
    refine_pose_lm,
    reprojection_errors,
    reprojection_residuals,
)
from nbcalib.metrics import pose_errors
from nbcalib.transforms import invert_T, make_T, se3_exp, so3_exp, transform_points
from tests.tolerances import TOL

#: a camera looking along LiDAR +x, 10 cm beside it, slightly turned
T_TRUE = se3_exp(np.array([0.05, -0.08, 0.03, 0.02, -0.03, 0.01])) @ make_T(
    np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]), np.zeros(3)
)


def _visible_points(camera, T_camera_lidar, rng, n, ranges=(2.0, 30.0)):
    uv = rng.uniform([0, 0], [camera.width - 1, camera.height - 1], (3 * n, 2))
    b = camera.unproject(uv)
    ok = np.all(np.isfinite(b), axis=1)
    uv, b = uv[ok][:n], b[ok][:n]
    points_camera = b * rng.uniform(*ranges, (len(b), 1))
    return uv, transform_points(invert_T(T_camera_lidar), points_camera)


@pytest.mark.parametrize("model", CAMERA_MODELS)
def test_jacobian_matches_finite_differences(model, rng):
    camera = example_camera(model, 640, 480)
    uv, points = _visible_points(camera, T_TRUE, rng, 30)
    T = se3_exp(np.array([0.02, 0.01, -0.03, 0.01, 0.02, -0.01])) @ T_TRUE
    _r, J, valid = reprojection_residuals(camera, T, uv, points)
    assert valid.all() and J.shape == (len(uv), 2, 6)
    h = 1e-6
    J_num = np.empty_like(J)
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        r_plus, _, _ = reprojection_residuals(camera, se3_exp(d) @ T, uv, points)
        r_minus, _, _ = reprojection_residuals(camera, se3_exp(-d) @ T, uv, points)
        J_num[:, :, k] = (r_plus - r_minus) / (2 * h)
    scale = np.abs(J).max(axis=(1, 2), keepdims=True)  # pixels per metre can be ~1e3
    assert_allclose(J / scale, J_num / scale, **TOL["jacobian_vs_finite_diff"])


def test_cauchy_loss():
    s = np.array([0.0, 1.0, 100.0, 1e6])
    assert_allclose(cauchy_loss(s, 10.0), 100.0 * np.log1p(s / 100.0))
    assert cauchy_loss(1e-6, 10.0) == pytest.approx(1e-6, rel=1e-6)  # quadratic near 0
    assert cauchy_loss(1e8, 10.0) < 1e4  # logarithmic far out


@pytest.mark.parametrize("model", ["plumb_bob", "fisheye", "omnidir", "equirectangular"])
def test_lm_recovers_the_pose_from_noise_free_correspondences(model, rng):
    camera = example_camera(model, 640, 480)
    uv, points = _visible_points(camera, T_TRUE, rng, 40)
    start = se3_exp(np.array([0.2, -0.1, 0.15, 0.05, -0.04, 0.03])) @ T_TRUE
    result = refine_pose_lm(camera, uv, points, start)
    assert result.converged and result.cost < 1e-12 < result.initial_cost
    delta = pose_errors(result.T_camera_lidar, T_TRUE)
    assert delta["translation_error_m"] < TOL["pose_noise_free"]["atol"]
    assert np.radians(delta["rotation_error_deg"]) < TOL["pose_noise_free"]["atol"]
    assert np.all(result.errors < 1e-6)


def test_lm_ignores_outliers_through_the_cauchy_kernel(rng):
    camera = example_camera("pinhole", 640, 480)
    uv, points = _visible_points(camera, T_TRUE, rng, 60)
    uv_noisy = uv + rng.normal(0, 0.5, uv.shape)
    n_out = 60
    uv_out = rng.uniform([0, 0], [639, 479], (n_out, 2))
    points_out = rng.normal(size=(n_out, 3)) * 10.0
    start = se3_exp(np.array([0.1, 0.1, -0.1, 0.01, 0.01, 0.02])) @ T_TRUE
    result = refine_pose_lm(
        camera,
        np.concatenate([uv_noisy, uv_out]),
        np.concatenate([points, points_out]),
        start,
        robust_kernel_width=5.0,
    )
    delta = pose_errors(result.T_camera_lidar, T_TRUE)
    assert delta["rotation_error_deg"] < 0.05 and delta["translation_error_m"] < 0.02
    assert np.median(result.errors[:60]) < 1.0


def test_weights_scale_each_term(rng):
    camera = example_camera("fisheye", 640, 480)
    uv, points = _visible_points(camera, T_TRUE, rng, 40)
    uv_bad = uv.copy()
    uv_bad[:10] += rng.normal(0, 30.0, (10, 2))  # ten wrong keypoints
    start = se3_exp(np.array([0.05, 0.05, -0.05, 0.01, 0.02, 0.01])) @ T_TRUE
    weights = np.r_[np.zeros(10), np.ones(30)]
    result = refine_pose_lm(camera, uv_bad, points, start, weights=weights)
    delta = pose_errors(result.T_camera_lidar, T_TRUE)  # zero weight: as if left out
    assert delta["rotation_error_deg"] < 1e-6 and delta["translation_error_m"] < 1e-6
    unweighted = refine_pose_lm(camera, uv_bad, points, start)
    halved = refine_pose_lm(camera, uv_bad, points, start, weights=np.full(40, 0.5))
    assert halved.cost == pytest.approx(0.5 * unweighted.cost, rel=1e-6)
    with pytest.raises(ValueError, match="weights"):
        refine_pose_lm(camera, uv, points, start, weights=-np.ones(40))


def test_points_behind_the_camera_cost_a_constant_and_do_not_crash(rng):
    camera = example_camera("plumb_bob", 640, 480)
    uv, points = _visible_points(camera, T_TRUE, rng, 30)
    behind = -points[:5] * 3.0  # through the LiDAR origin: behind the camera
    points_all = np.concatenate([points, behind])
    uv_all = np.concatenate([uv, uv[:5]])
    errors, valid = reprojection_errors(camera, T_TRUE, uv_all, points_all)
    assert valid[:30].all() and not valid[30:].any() and np.all(np.isinf(errors[30:]))
    r, _J, v = reprojection_residuals(camera, T_TRUE, uv_all, points_all)
    assert np.all(np.isnan(r[30:])) and np.array_equal(v, valid)
    start = se3_exp(np.array([0.05, 0.0, 0.0, 0.0, 0.02, 0.0])) @ T_TRUE
    result = refine_pose_lm(camera, uv_all, points_all, start)
    delta = pose_errors(result.T_camera_lidar, T_TRUE)
    assert delta["rotation_error_deg"] < 1e-6 and delta["translation_error_m"] < 1e-6
    # everything behind the camera: a finite cost, no step, no exception
    flipped = make_T(so3_exp(np.array([0.0, np.pi, 0.0])), np.zeros(3)) @ T_TRUE
    stuck = refine_pose_lm(camera, uv, points, flipped, max_iterations=5)
    assert np.isfinite(stuck.cost) and np.all(np.isinf(stuck.errors))


def test_bad_inputs():
    camera = example_camera("pinhole", 64, 48)
    with pytest.raises(ValueError, match="shape"):
        refine_pose_lm(camera, np.zeros((3, 2)), np.zeros((4, 3)), np.eye(4))
    with pytest.raises(ValueError, match="robust_kernel_width"):
        refine_pose_lm(camera, np.zeros((3, 2)), np.ones((3, 3)), np.eye(4), robust_kernel_width=0)
    with pytest.raises(ValueError):
        refine_pose_lm(camera, np.zeros((3, 2)), np.ones((3, 3)), np.zeros((4, 4)))
    with pytest.raises(ValueError, match="CameraModel"):
        reprojection_errors("pinhole", np.eye(4), np.zeros((3, 2)), np.ones((3, 3)))
