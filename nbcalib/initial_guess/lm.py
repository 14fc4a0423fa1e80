r"""Robust reprojection-error minimisation over ``T_camera_lidar`` (paper Eq. 1).

.. math::

    T^* = \arg\min_T \sum_j \rho\left(\|\pi(T p_j) - x_j\|^2\right), \qquad
    \rho(s) = a^2 \log(1 + s / a^2)

with the Cauchy kernel of width ``a`` pixels (``robust_kernel_width``; Ceres's ``CauchyLoss(a)``
as the reference toolbox uses), over **all** correspondences: the kernel suppresses the outliers.

Solver: Levenberg-Marquardt with iteratively reweighted normal equations. At the current pose each
correspondence gets the weight ``w_j = rho'(s_j) = 1 / (1 + s_j / a^2)``; the step ``delta``
solves ``(H + lambda diag(H)) delta = -g`` with ``H = sum w_j J_j^T J_j`` and
``g = sum w_j J_j^T r_j``, and is applied on the left, ``T <- se3_exp(delta) @ T``
(docs/conventions.md section 3). The Jacobian of a residual ``r_j = pi(p_c) - x_j`` with
``p_c = T p_j`` is the camera's analytic ``d uv / d p_c`` times ``[I_3, -[p_c]x]``.

A point that the pose puts behind the camera (or outside the model's domain) has no residual; it
costs a constant, ``rho`` of the squared image diagonal, so that no step gains by hiding points.
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.transforms import se3_exp, validate_T

__all__ = [
    "LMResult",
    "cauchy_loss",
    "refine_pose_lm",
    "reprojection_errors",
    "reprojection_residuals",
]


def cauchy_loss(squared_error, width: float) -> np.ndarray:
    """Cauchy kernel ``rho(s) = a^2 log(1 + s / a^2)`` of squared errors ``s`` (pixels^2).

    Parameters
    ----------
    squared_error : array_like
        Squared reprojection errors, pixels^2.
    width : float
        Kernel width ``a``, pixels: errors well below it count as squared, errors above it grow
        only logarithmically.

    Returns
    -------
    ndarray, float64
        Same shape as ``squared_error``, pixels^2.
    """
    a2 = float(width) ** 2
    return a2 * np.log1p(np.asarray(squared_error, dtype=np.float64) / a2)


def _prepare(camera, T_camera_lidar, uv_camera, points_lidar):
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    T = validate_T(T_camera_lidar, name="T_camera_lidar")
    uv = np.ascontiguousarray(uv_camera, dtype=np.float64)
    points = np.ascontiguousarray(points_lidar, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv_camera must have shape (M, 2), got {uv.shape}")
    if points.shape != (uv.shape[0], 3):
        raise ValueError(f"points_lidar must have shape ({uv.shape[0]}, 3), got {points.shape}")
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(points))):
        raise ValueError("uv_camera and points_lidar must be finite")
    return T, uv, points


def _residuals(camera, T, uv, points, *, jacobian: bool):
    points_camera = points @ T[:3, :3].T + T[:3, 3]
    if not jacobian:
        proj, valid = camera.project(points_camera)
        return proj - uv, None, valid
    proj, d_uv_d_p, valid = camera.project_jacobian(points_camera)
    J = np.empty((len(uv), 2, 6))
    J[:, :, :3] = d_uv_d_p
    # row a of d_uv_d_p times -[p_c]x is (p_c x j_a)^T
    J[:, :, 3:] = np.cross(points_camera[:, None, :], d_uv_d_p)
    return proj - uv, J, valid


def reprojection_residuals(
    camera: CameraModel, T_camera_lidar, uv_camera, points_lidar
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Reprojection residuals and their Jacobian with respect to a left perturbation.

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    T_camera_lidar : array_like of shape (4, 4)
        ``p_camera = T_camera_lidar @ p_lidar``.
    uv_camera : array_like of shape (M, 2)
        Camera keypoints, pixels.
    points_lidar : array_like of shape (M, 3)
        Their 3-D points in the LiDAR frame, metres.

    Returns
    -------
    residuals : ndarray of shape (M, 2), float64
        ``pi(T p_j) - x_j``, pixels; NaN where the projection is invalid.
    jacobian : ndarray of shape (M, 2, 6), float64
        ``d residual / d delta`` for ``T <- se3_exp(delta) @ T``, ``delta = [v, omega]``
        (pixels per metre, pixels per radian); NaN where invalid.
    valid : ndarray of shape (M,), bool
        The projection is valid (in front of the camera, inside the model's domain).
    """
    T, uv, points = _prepare(camera, T_camera_lidar, uv_camera, points_lidar)
    return _residuals(camera, T, uv, points, jacobian=True)


def reprojection_errors(
    camera: CameraModel, T_camera_lidar, uv_camera, points_lidar
) -> tuple[np.ndarray, np.ndarray]:
    """Reprojection error of each correspondence, pixels.

    Returns
    -------
    errors : ndarray of shape (M,), float64
        ``||pi(T p_j) - x_j||``, pixels; inf where the projection is invalid.
    valid : ndarray of shape (M,), bool
    """
    T, uv, points = _prepare(camera, T_camera_lidar, uv_camera, points_lidar)
    r, _, valid = _residuals(camera, T, uv, points, jacobian=False)
    errors = np.full(len(uv), np.inf)
    errors[valid] = np.hypot(r[valid, 0], r[valid, 1])
    return errors, valid


@dataclass(frozen=True)
class LMResult:
    """Outcome of :func:`refine_pose_lm`.

    Attributes
    ----------
    T_camera_lidar : ndarray of shape (4, 4), float64
        The refined pose.
    cost : float
        Final ``sum rho(s_j)``, pixels^2.
    initial_cost : float
        Cost at the start pose.
    iterations : int
        Accepted plus rejected LM steps.
    converged : bool
        Stopped by a tolerance (not by ``max_iterations``).
    errors : ndarray of shape (M,), float64
        Final reprojection errors, pixels (inf where invalid).
    """

    T_camera_lidar: np.ndarray
    cost: float
    initial_cost: float
    iterations: int
    converged: bool
    errors: np.ndarray


def refine_pose_lm(
    camera: CameraModel,
    uv_camera,
    points_lidar,
    T_camera_lidar_init,
    *,
    robust_kernel_width: float = 10.0,
    weights=None,
    max_iterations: int = 100,
    function_tolerance: float = 1e-10,
    step_tolerance: float = 1e-10,
    gradient_tolerance: float = 1e-10,
) -> LMResult:
    """Minimise the Cauchy-robustified reprojection error over ``T_camera_lidar`` (paper Eq. 1).

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    uv_camera : array_like of shape (M, 2)
        Camera keypoints, pixels.
    points_lidar : array_like of shape (M, 3)
        Their 3-D points in the LiDAR frame, metres.
    T_camera_lidar_init : array_like of shape (4, 4)
        Start pose (e.g. the RANSAC rotation with zero translation).
    robust_kernel_width : float, optional
        Cauchy width ``a``, pixels.
    weights : array_like of shape (M,), optional
        Non-negative weight of each correspondence's term (e.g. a match confidence); the cost
        becomes ``sum c_j rho(s_j)``. Default: all 1 (paper Eq. 1).
    max_iterations : int, optional
        Upper bound on LM steps (accepted or rejected).
    function_tolerance : float, optional
        Stop when an accepted step lowers the cost by less than this fraction.
    step_tolerance : float, optional
        Stop when the step's norm (metres and radians) is below this.
    gradient_tolerance : float, optional
        Stop when the largest gradient component is below this times the cost.

    Returns
    -------
    LMResult
    """
    T, uv, points = _prepare(camera, T_camera_lidar_init, uv_camera, points_lidar)
    if not (np.isfinite(robust_kernel_width) and robust_kernel_width > 0.0):
        raise ValueError(f"robust_kernel_width must be > 0 pixels, got {robust_kernel_width}")
    max_iterations = operator.index(max_iterations)
    if weights is None:
        c = np.ones(len(uv))
    else:
        c = np.asarray(weights, dtype=np.float64)
        if c.shape != (len(uv),) or not np.all(np.isfinite(c)) or np.any(c < 0.0):
            raise ValueError(f"weights must be ({len(uv)},) finite and >= 0, got shape {c.shape}")
    a2 = float(robust_kernel_width) ** 2
    s_invalid = float(camera.width) ** 2 + float(camera.height) ** 2

    def evaluate(T_eval, jacobian):
        r, J, valid = _residuals(camera, T_eval, uv, points, jacobian=jacobian)
        s = np.where(valid, np.sum(np.where(valid[:, None], r, 0.0) ** 2, axis=1), s_invalid)
        return float(np.sum(c * a2 * np.log1p(s / a2))), r, J, valid, s

    cost, r, J, valid, s = evaluate(T, True)
    initial_cost = cost
    lam = 1e-4
    converged = False
    iterations = 0
    while iterations < max_iterations:
        w = np.where(valid, c / (1.0 + s / a2), 0.0)
        Jv, rv, wv = J[valid], r[valid], w[valid]
        H = np.einsum("m,mki,mkj->ij", wv, Jv, Jv)
        g = np.einsum("m,mki,mk->i", wv, Jv, rv)
        if np.max(np.abs(g), initial=0.0) <= gradient_tolerance * max(cost, 1e-300):
            converged = True
            break
        diag = np.diag(H).copy()
        diag = np.maximum(diag, 1e-12 * max(diag.max(initial=0.0), 1.0))
        accepted = False
        while iterations < max_iterations:
            iterations += 1
            try:
                delta = np.linalg.solve(H + lam * np.diag(diag), -g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            T_new = se3_exp(delta) @ T
            cost_new, r_new, J_new, valid_new, s_new = evaluate(T_new, True)
            if cost_new < cost:
                decrease = (cost - cost_new) / max(cost, 1e-300)
                T, cost, r, J, valid, s = T_new, cost_new, r_new, J_new, valid_new, s_new
                lam = max(lam / 10.0, 1e-12)
                accepted = True
                if decrease < function_tolerance or np.linalg.norm(delta) < step_tolerance:
                    converged = True
                break
            lam *= 10.0
            if lam > 1e12 or np.linalg.norm(delta) < step_tolerance:
                converged = True  # no step lowers the cost: a minimum up to rounding
                break
        if converged or not accepted:
            break
    errors = np.full(len(uv), np.inf)
    errors[valid] = np.hypot(r[valid, 0], r[valid, 1])
    return LMResult(
        T_camera_lidar=T,
        cost=cost,
        initial_cost=initial_cost,
        iterations=iterations,
        converged=converged,
        errors=errors,
    )
