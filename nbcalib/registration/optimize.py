"""Optimisers over ``T_camera_lidar`` for the NID cost: Nelder-Mead and box-bounded L-BFGS.

Both work in a local chart around the pose ``T0`` at which an outer iteration starts:
``T(delta) = exp(delta) @ T0`` with ``delta = [v, omega]`` (docs/conventions.md). The chart is
bounded by a trust box, ``|v_i| <= max_translation`` and ``|omega_i| <= max_rotation`` (the
reference toolbox rejects evaluations farther than 0.2 m / 2 degrees from ``T0``; bounds do the
same thing without making the line search fail).

- :func:`minimize_nelder_mead`: derivative-free, the paper's choice, for the hard-binned NID.
  SciPy's textbook Nelder-Mead (the reference's variant computes an outside-contraction point
  where inside contraction is meant; we do not copy that), started from a simplex of
  ``init_step`` along each axis.
- :func:`minimize_lbfgs`: quasi-Newton with the exact gradient of the smooth NID. The cost's
  gradient is with respect to a left perturbation at ``T(delta)``; the chain rule through the
  SE(3) exponential (``d/d delta = J_l(delta)^T g``) makes it the gradient in the chart. The
  chart is scaled to :data:`LBFGS_SCALE` (1 cm, 0.05 degrees: an equal move of points about
  11 m away): unscaled, a rotation's gradient is ~50 times a translation's, the first quasi-
  Newton steps were nearly pure rotations and the search stopped on its relative-reduction
  test with the translation short of the minimum (10 synthetic frames from 1 deg / 5 cm: 2.0 cm
  from the truth instead of 0.9; docs/BENCHMARKS.md 5.4).

Given a ``trust_region`` (:class:`nbcalib.registration.trust.TrustRegion`, the bound of the whole
run around its start), both return only poses inside it: the box is shrunk to what can reach the
region, a pose outside is evaluated as the cost at its projection plus a penalty, and the pose
found is projected onto the region (and its cost evaluated there when it moved).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.optimize import minimize

from nbcalib.transforms import hat, se3_exp, so3_left_jacobian

if TYPE_CHECKING:
    from nbcalib.registration.trust import TrustRegion

__all__ = [
    "LBFGS_SCALE",
    "InnerResult",
    "minimize_lbfgs",
    "minimize_nelder_mead",
    "se3_left_jacobian",
]

#: Units of L-BFGS's chart variables: metres for ``v``, radians for ``omega`` (1 cm, 0.05 deg).
LBFGS_SCALE = np.array([0.01] * 3 + [math.radians(0.05)] * 3)

#: Units of the intrinsics' chart variables when they are refined with the pose (issue 47): the
#: log focal scale in 0.1 % (about the pixel shift of a 1 cm forward move of a camera 10 m from
#: the scene at the image's edge), the principal point in pixels.
LBFGS_INTRINSICS_SCALE = np.array([1e-3, 1.0, 1.0])


@dataclass
class InnerResult:
    """Outcome of one inner optimisation in the chart around ``T0``."""

    T_camera_lidar: np.ndarray
    value: float
    iterations: int
    evaluations: int
    converged: bool
    message: str
    history: list[float] = field(default_factory=list)
    #: The intrinsics' offset found, when they were refined with the pose (else None).
    intrinsics: np.ndarray | None = None


def se3_left_jacobian(xi: np.ndarray) -> np.ndarray:
    """Left Jacobian ``J`` of SE(3) at ``xi = [v, omega]``: ``exp(xi + d) = exp(J d) exp(xi)``.

    Closed form (Barfoot, *State Estimation for Robotics*, eq. 7.86, whose tangent order
    ``[rho, phi]`` is nbcalib's ``[v, omega]``): ``J = [[J_l, Q], [0, J_l]]`` with ``J_l`` the
    SO(3) left Jacobian of ``omega`` and ``Q(v, omega)`` below; Taylor coefficients near 0.
    """
    xi = np.asarray(xi, dtype=np.float64)
    v, omega = xi[:3], xi[3:]
    theta = float(np.linalg.norm(omega))
    P, W = hat(v), hat(omega)
    if theta < 1e-3:
        t2 = theta * theta
        a, b, c = 1 / 6 - t2 / 120, 1 / 24 - t2 / 720, 1 / 120 - t2 / 2520
    else:
        s, co = math.sin(theta), math.cos(theta)
        a = (theta - s) / theta**3
        b = (theta * theta + 2 * co - 2) / (2 * theta**4)
        c = (2 * theta - 3 * s + theta * co) / (2 * theta**5)
    WP, PW, WW = W @ P, P @ W, W @ W
    WPW = WP @ W
    Q = 0.5 * P + a * (WP + PW + WPW) + b * (WW @ P + PW @ W - 3 * WPW) + c * (WPW @ W + WW @ PW)
    J = np.zeros((6, 6))
    J[:3, :3] = J[3:, 3:] = so3_left_jacobian(omega)
    J[:3, 3:] = Q
    return J


def _bounds(max_translation: float, max_rotation: float):
    return [(-max_translation, max_translation)] * 3 + [(-max_rotation, max_rotation)] * 3


def _in_region(result: InnerResult, region, cost) -> InnerResult:
    """``result`` with its pose projected onto ``region`` and its value the cost there.

    Inside the region the result is returned as it is; a projected pose costs one evaluation
    more (counted).
    """
    if region is None or region.contains(result.T_camera_lidar):
        return result
    result.T_camera_lidar = region.project(result.T_camera_lidar)
    result.value = float(cost(result.T_camera_lidar))
    result.evaluations += 1
    result.message = f"{result.message} (projected onto the trust region)"
    return result


def minimize_nelder_mead(
    cost: Callable[[np.ndarray], float],
    T0: np.ndarray,
    *,
    init_step: float = 1e-3,
    max_translation: float = 0.2,
    max_rotation: float = math.radians(2.0),
    max_evaluations: int = 2000,
    xatol: float = 1e-6,
    fatol: float = 1e-8,
    trust_region: TrustRegion | None = None,
) -> InnerResult:
    """Minimise ``cost(T)`` over ``T = exp(delta) @ T0`` with Nelder-Mead.

    Parameters
    ----------
    cost : callable
        ``cost(T_camera_lidar (4, 4)) -> float``.
    T0 : ndarray of shape (4, 4)
        Start pose (centre of the chart).
    init_step : float, optional
        Initial simplex size along each tangent axis (metres / radians; reference: 1e-3).
    trust_region : TrustRegion, optional
        The region the result must lie in (``T0`` inside it; module docstring).
    """
    history: list[float] = []
    objective = cost
    if trust_region is not None:
        objective = trust_region.penalised_value(cost)
        max_translation, max_rotation = trust_region.chart_bounds(T0, max_translation, max_rotation)

    def f(delta):
        value = objective(se3_exp(delta) @ T0)
        history.append(value)
        return value

    simplex = np.vstack([np.zeros(6), init_step * np.eye(6)])
    res = minimize(
        f,
        np.zeros(6),
        method="Nelder-Mead",
        bounds=_bounds(max_translation, max_rotation),
        options={
            "initial_simplex": simplex,
            "xatol": xatol,
            "fatol": fatol,
            "maxfev": max_evaluations,
            "adaptive": False,
        },
    )
    result = InnerResult(
        se3_exp(res.x) @ T0,
        float(res.fun),
        int(res.nit),
        int(res.nfev),
        bool(res.success),
        str(res.message),
        history,
    )
    return _in_region(result, trust_region, cost)


def minimize_lbfgs(
    cost_and_grad: Callable[[np.ndarray], tuple[float, np.ndarray]],
    T0: np.ndarray,
    *,
    max_translation: float = 0.2,
    max_rotation: float = math.radians(2.0),
    max_iterations: int = 50,
    gtol: float = 1e-10,
    ftol: float = 1e-7,
    trust_region: TrustRegion | None = None,
    intrinsics=None,
    intrinsics_bounds=None,
) -> InnerResult:
    """Minimise ``cost(T)`` over ``T = exp(delta) @ T0`` with box-bounded L-BFGS.

    Parameters
    ----------
    cost_and_grad : callable
        ``f(T_camera_lidar) -> (value, grad)`` with ``grad`` (6,) the derivative with respect to
        a left perturbation ``exp(d) @ T`` at ``T`` (as :meth:`NIDCost.value_and_grad`); with
        ``intrinsics``, ``f(T_camera_lidar, intrinsics) -> (value, grad (6 + n,))``.
    T0 : ndarray of shape (4, 4)
        Start pose (centre of the chart).
    trust_region : TrustRegion, optional
        The region the result must lie in (``T0`` inside it; module docstring).
    intrinsics : array_like of shape (n,), optional
        Refine these intrinsics with the pose, from this start (issue 47: ``[lambda]`` or
        ``[lambda, cx, cy]``, :func:`nbcalib.registration.nid.offset_params`), in a chart
        scaled by :data:`LBFGS_INTRINSICS_SCALE`; their value found is the result's
        :attr:`InnerResult.intrinsics`.
    intrinsics_bounds : sequence of (low, high), optional
        Bounds of each intrinsic (default none).
    """
    history: list[float] = []
    objective = cost_and_grad
    theta0 = None if intrinsics is None else np.asarray(intrinsics, dtype=np.float64).ravel()
    n_intr = 0 if theta0 is None else theta0.size
    k_intr = LBFGS_INTRINSICS_SCALE[:n_intr]
    found: dict = {}
    if n_intr:

        def pose_cost_at(theta):  # the cost of the pose at theta, its gradient kept aside
            def pose_cost(T):
                value, g = cost_and_grad(T, theta)
                found["g_intr"] = np.asarray(g[6:], dtype=np.float64)
                return value, g[:6]

            return pose_cost

    if trust_region is not None:
        max_translation, max_rotation = trust_region.chart_bounds(T0, max_translation, max_rotation)
        if not n_intr:
            objective = trust_region.penalised_value_and_grad(cost_and_grad)

    scale = LBFGS_SCALE

    def f(x):
        delta = x[:6] * scale
        if n_intr:
            theta = x[6:] * k_intr
            pose_cost = pose_cost_at(theta)
            if trust_region is not None:
                pose_cost = trust_region.penalised_value_and_grad(pose_cost)
            value, g = pose_cost(se3_exp(delta) @ T0)
            history.append(value)
            g_pose = (se3_left_jacobian(delta).T @ g) * scale
            return value, np.concatenate([g_pose, found["g_intr"] * k_intr])
        value, g = objective(se3_exp(delta) @ T0)
        history.append(value)
        return value, (se3_left_jacobian(delta).T @ g) * scale

    bounds = [
        (lo / k, hi / k) for (lo, hi), k in zip(_bounds(max_translation, max_rotation), scale)
    ]
    x0 = np.zeros(6)
    if n_intr:
        x0 = np.concatenate([x0, theta0 / k_intr])
        limits = intrinsics_bounds or [(-np.inf, np.inf)] * n_intr
        bounds += [(lo / k, hi / k) for (lo, hi), k in zip(limits, k_intr)]
    res = minimize(
        f,
        x0,
        jac=True,
        method="L-BFGS-B",
        bounds=bounds,
        options={"maxiter": max_iterations, "gtol": gtol, "ftol": ftol},
    )
    result = InnerResult(
        se3_exp(res.x[:6] * scale) @ T0,
        float(res.fun),
        int(res.nit),
        int(res.nfev),
        bool(res.success),
        str(res.message),
        history,
        None if not n_intr else res.x[6:] * k_intr,
    )
    if n_intr:
        theta = result.intrinsics
        return _in_region(result, trust_region, lambda T: cost_and_grad(T, theta)[0])
    return _in_region(result, trust_region, lambda T: cost_and_grad(T)[0])
