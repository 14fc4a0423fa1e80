"""The trust region of fine registration: how far a whole run may move from its start.

A run of :func:`nbcalib.registration.refine.refine` may not leave a region around its initial
guess ``T_init``, measured as :func:`nbcalib.transforms.pose_error` measures
``T_lidar_camera``: the camera centre (in the LiDAR frame) within ``translation`` metres of the
start's, and the camera's rotation within ``rotation_deg`` degrees of the start's. The two parts
are independent (the camera centre does not depend on the rotation), so the region is a ball of
centres times a ball of rotations, and its nearest point to a pose outside is found part by
part: the centre pulled radially onto its sphere, the rotation shortened along its own geodesic
(:meth:`TrustRegion.project`).

The inner optimisers (:mod:`nbcalib.registration.optimize`) work in a chart
``T(delta) = exp(delta) @ T0`` around the pose ``T0`` at which an outer iteration starts; the
region enters them three ways:

1. **Chart bounds.** Their box bounds are shrunk to the part of the chart that can reach the
   region (:meth:`TrustRegion.chart_bounds`: a safe superset, by the triangle inequality). With
   the defaults (a 0.5 m / 5 degree region, a 0.2 m / 2 degree box) they never shrink.
2. **Penalised cost.** A pose outside is evaluated as the cost at its projection onto the
   region plus a penalty that grows linearly with the excess (one NID unit per centimetre and
   per 0.1 degree): continuous, lower inside than anywhere outside, so the minimum of the
   penalised cost lies in the region. The gradient (for L-BFGS) is the chain rule through the
   projection plus the penalty's (:meth:`TrustRegion.penalised_value_and_grad`). Inside the
   region the cost and its gradient are passed through untouched (bit for bit).
3. **Projection.** The pose an optimiser returns is projected onto the region (it may end at a
   penalised pose outside) and its cost evaluated there.

A result whose distance from the start is within :data:`BOUNDARY_TOLERANCE` of the region's
size (either part) lies *on the trust boundary*: the optimum may lie beyond it, and the
verdict says so (:mod:`nbcalib.report.quality`).

Example
-------
>>> region = TrustRegion(T_init, translation=0.5, rotation_deg=5.0)      # doctest: +SKIP
>>> region.distances(T), region.on_boundary(T), region.project(T)        # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from nbcalib.transforms import (
    invert_T,
    pose_error,
    so3_exp,
    so3_left_jacobian,
    so3_left_jacobian_inv,
    so3_log,
    validate_T,
)

__all__ = ["BOUNDARY_TOLERANCE", "PENALTY_PER_METRE", "PENALTY_PER_RADIAN", "TrustRegion"]

#: A distance within this fraction of the region's size (1 %) is on the boundary: L-BFGS stops a
#: little short of the kink the penalty makes at the edge (0.4 % in tests/test_trust.py).
BOUNDARY_TOLERANCE = 0.01
#: Penalty per metre of the camera centre outside the region (one NID unit per centimetre).
PENALTY_PER_METRE = 100.0
#: Penalty per radian of rotation outside the region (one NID unit per 0.1 degree).
PENALTY_PER_RADIAN = 1.0 / math.radians(0.1)
#: Relative slack under which a pose counts as inside (rounding of a projected pose).
_INSIDE_SLACK = 1e-12


class TrustRegion:
    """The poses within ``translation`` metres and ``rotation_deg`` degrees of ``T_init``.

    Parameters
    ----------
    T_init : array_like of shape (4, 4)
        The run's initial guess, ``p_camera = T_init @ p_lidar``.
    translation : float
        Largest distance of the camera centre from the start's, metres (>= 0).
    rotation_deg : float
        Largest rotation from the start's, degrees (>= 0, below 180).
    """

    def __init__(self, T_init, translation: float, rotation_deg: float):
        if not translation >= 0 or not 0 <= rotation_deg < 180:
            raise ValueError(
                f"a trust region needs translation >= 0 and rotation in [0, 180) degrees, got "
                f"{translation} m / {rotation_deg} deg"
            )
        self.T_init = validate_T(np.asarray(T_init, dtype=np.float64), "T_init").copy()
        self.translation = float(translation)
        self.rotation_deg = float(rotation_deg)
        self.rotation = math.radians(self.rotation_deg)
        self._T_lidar_camera_init = invert_T(self.T_init)
        self._centre_init = self._T_lidar_camera_init[:3, 3].copy()
        self._R_init = self.T_init[:3, :3].copy()

    def __repr__(self) -> str:
        return f"TrustRegion({self.translation} m, {self.rotation_deg} deg)"

    # ------------------------------------------------------------------ measures
    def distances(self, T) -> tuple[float, float]:
        """Distance of ``T`` from the start: metres (camera centre) and degrees (rotation)."""
        dt, dr = pose_error(invert_T(np.asarray(T, dtype=np.float64)), self._T_lidar_camera_init)
        return float(dt), float(dr)

    def contains(self, T) -> bool:
        """``T`` lies in the region (up to rounding)."""
        dt, dr = self.distances(T)
        return dt <= self._limit(self.translation) and dr <= self._limit(self.rotation_deg)

    def on_boundary(self, T, tolerance: float = BOUNDARY_TOLERANCE) -> bool:
        """``T`` lies on the region's edge (or beyond it), within ``tolerance`` of its size."""
        return on_trust_boundary(
            self.distances(T), (self.translation, self.rotation_deg), tolerance
        )

    @staticmethod
    def _limit(size: float) -> float:
        return size * (1.0 + _INSIDE_SLACK) + 1e-15

    def _parts(self, T: np.ndarray):
        """(centre offset, its norm, rotation vector of ``R R_init^T``, its angle in radians)."""
        R, t = T[:3, :3], T[:3, 3]
        offset = -R.T @ t - self._centre_init
        phi = so3_log(R @ self._R_init.T)
        return offset, float(np.linalg.norm(offset)), phi, float(np.linalg.norm(phi))

    def _outside(self, d: float, theta: float) -> tuple[bool, bool]:
        return d > self._limit(self.translation), theta > self._limit(self.rotation)

    def project(self, T) -> np.ndarray:
        """The nearest pose of the region to ``T`` (``T`` itself, a copy, when inside)."""
        T = np.asarray(T, dtype=np.float64)
        offset, d, phi, theta = self._parts(T)
        out_t, out_r = self._outside(d, theta)
        if not (out_t or out_r):
            return T.copy()
        return self._projected(T, offset, d, phi, theta, out_t, out_r)

    def _projected(self, T, offset, d, phi, theta, out_t, out_r) -> np.ndarray:
        R = T[:3, :3]
        if out_r:
            R = so3_exp(phi * (self.rotation / theta)) @ self._R_init
        centre = self._centre_init + (offset * (self.translation / d) if out_t else offset)
        P = np.eye(4)
        P[:3, :3] = R
        P[:3, 3] = -R @ centre
        return P

    # ------------------------------------------------------------------ costs
    def _penalty(self, d: float, theta: float) -> float:
        return PENALTY_PER_METRE * max(d - self.translation, 0.0) + PENALTY_PER_RADIAN * max(
            theta - self.rotation, 0.0
        )

    def penalised_value(self, cost: Callable[[np.ndarray], float]) -> Callable:
        """``cost`` inside the region; outside, the cost at the projection plus a penalty."""

        def value(T):
            T = np.asarray(T, dtype=np.float64)
            offset, d, phi, theta = self._parts(T)
            out_t, out_r = self._outside(d, theta)
            if not (out_t or out_r):
                return cost(T)
            P = self._projected(T, offset, d, phi, theta, out_t, out_r)
            return cost(P) + self._penalty(d, theta)

        return value

    def penalised_value_and_grad(
        self, cost_and_grad: Callable[[np.ndarray], tuple[float, np.ndarray]]
    ) -> Callable:
        """As :meth:`penalised_value`, with the gradient w.r.t. a left perturbation of ``T``.

        ``cost_and_grad(T) -> (value, grad)``, ``grad`` (6,) w.r.t. ``exp([v, omega]) @ T``.
        To first order a left perturbation moves the camera centre by ``-R^T v`` and the
        rotation ``R R_init^T`` by ``exp(omega)`` on the left, independently; the projection
        scales the centre's offset to the sphere (Jacobian ``(r / d)(I - n n^T)``) and the
        rotation vector ``phi`` to the rotation limit (``(r / theta)(I - m m^T)`` in
        ``phi``, with the SO(3) left Jacobians between ``phi`` and the left perturbation).
        """

        def value_and_grad(T):
            T = np.asarray(T, dtype=np.float64)
            offset, d, phi, theta = self._parts(T)
            out_t, out_r = self._outside(d, theta)
            if not (out_t or out_r):
                return cost_and_grad(T)
            P = self._projected(T, offset, d, phi, theta, out_t, out_r)
            value, g = cost_and_grad(P)
            g = np.asarray(g, dtype=np.float64)
            R, R_p = T[:3, :3], P[:3, :3]
            grad = np.empty(6)
            # translation: v at T moves the centre by -R^T v, the projected one by A (-R^T v),
            # and v_p = -R_p dc_p at the projected pose
            gv = R_p.T @ g[:3]
            if out_t:
                n = offset / d
                gv = (self.translation / d) * (gv - n * (n @ gv))
                gv = gv - PENALTY_PER_METRE * n  # d(d)/d(dc) = n, dc = -R^T v
            grad[:3] = R @ gv
            # rotation: omega at T changes phi by J_l(phi)^-1 omega, the projection scales phi,
            # and omega_p = J_l(phi_p) d(phi_p)
            gw = g[3:]
            if out_r:
                m = phi / theta
                phi_p = phi * (self.rotation / theta)
                h = so3_left_jacobian(phi_p).T @ gw
                h = (self.rotation / theta) * (h - m * (m @ h))
                gw = so3_left_jacobian_inv(phi).T @ h + PENALTY_PER_RADIAN * m  # d(theta) = m
            grad[3:] = gw
            return value + self._penalty(d, theta), grad

        return value_and_grad

    # ------------------------------------------------------------------ charts
    def chart_bounds(self, T0, max_translation: float, max_rotation: float) -> tuple[float, float]:
        """Box bounds of the chart ``exp([v, omega]) @ T0``, shrunk to what can reach the region.

        A pose of the chart in the region has ``|omega| <= rotation + theta_0`` (geodesic
        triangle inequality; ``theta_0`` is ``T0``'s rotation from the start) and
        ``|v| <= (translation + d_0) / sinc(theta / 2)``: its centre is
        ``c_0 - R_0^T J_r(omega) v`` and the smallest singular value of ``J_r(omega)`` is
        ``sinc(|omega| / 2)``, ``|omega|`` at most the box's diagonal. Each returned bound is the
        given one when that is smaller (with the defaults, always).

        Parameters
        ----------
        T0 : array_like of shape (4, 4)
            The chart's centre (in the region).
        max_translation, max_rotation : float
            The box's half-sizes, metres and radians.
        """
        _, d0, _, theta0 = self._parts(np.asarray(T0, dtype=np.float64))
        reach_r = self.rotation + theta0
        r_bound = max_rotation if max_rotation <= reach_r else reach_r
        half = 0.5 * math.sqrt(3.0) * r_bound
        shrink = math.sin(half) / half if half > 0 else 1.0
        reach_t = (self.translation + d0) / shrink
        t_bound = max_translation if max_translation <= reach_t else reach_t
        return t_bound, r_bound


def on_trust_boundary(
    distances: tuple[float, float],
    region: tuple[float, float],
    tolerance: float = BOUNDARY_TOLERANCE,
) -> bool:
    """Distances (metres, degrees) from the start within ``tolerance`` of a region's size."""
    (dt, dr), (rt, rr) = distances, region
    return dt >= rt * (1.0 - tolerance) or dr >= rr * (1.0 - tolerance)
