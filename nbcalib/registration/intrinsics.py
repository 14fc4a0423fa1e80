"""The camera's intrinsics refined with the extrinsic, and whether the frames can tell them apart.

``refine.intrinsics = "focal"`` or ``"focal,center"`` (issue 47): after fine registration of the
pose, one more L-BFGS stage at full resolution refines the pose and the intrinsics together over
every pair of the job (:func:`nbcalib.registration.refine.refine`), with the NID's exact
derivative in both (:func:`nbcalib.registration.nid.offset_params`). The intrinsics are an
offset ``theta`` of the given camera:

- ``lambda``: ``fx`` and ``fy`` times ``exp(lambda)`` (one focal scale: a pixel's aspect is a
  property of the sensor and rarely what a quick calibration gets wrong);
- ``cx, cy``: the principal point moved by that many pixels (``"focal,center"``).

**Why it needs many frames.** Seen from one place, a focal length a little long is much like a
camera a little forward: both spread the image about its centre. They differ in how that spread
depends on depth (a forward move enlarges near things more than far ones, a focal length
enlarges all alike), so frames that see the scene at several depths can tell them apart, and
one frame of a flat scene cannot. So the refinement says how well the job's frames separate them
(:func:`identifiability`), from the summed cost's curvature and the scatter of the minimum when
one pair is left out:

- ``correlation``: of ``lambda`` with the camera's forward translation ``tz`` in the inverse
  Hessian (how much the cost trades one for the other; +-1: not at all separated);
- the 95 % bounds of the focal scale and the principal point: the delete-one-pair jackknife of
  the joint minimum (one Newton step without each pair), as the report's leave-one-out.

A job whose bounds exceed ``intrinsics_max_focal_bound`` (or ``intrinsics_max_center_bound``)
keeps the given intrinsics and the pose fine registration found with them, and says so; a job of
fewer than :data:`MIN_PAIRS` pairs is refused before any work.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from nbcalib.camera import CameraModel, offset_intrinsics
from nbcalib.errors import InputError
from nbcalib.registration.config import INTRINSICS_MODES, RefineConfig
from nbcalib.transforms import se3_exp

__all__ = [
    "MIN_PAIRS",
    "IntrinsicsRefinement",
    "check_pairs",
    "identifiability",
    "intrinsics_bounds",
    "refined_camera",
]

#: Fewest pairs a refinement of the intrinsics runs on (the jackknife over pairs needs three).
MIN_PAIRS = 3

#: Pixels that each step of the joint Hessian's central differences moves the image by: a
#: rotation of ``STEP_PIXELS / fx`` radians, a focal scale moving the image's corners this
#: far, the principal point this far; translations 5 mm (the report's). The NID is smooth only
#: at the B-spline's scale and its curvature along a rotation undone by a move of the principal
#: point is small: steps of unequal size (0.1 degree, about a pixel, beside half a pixel) gave
#: negative curvatures there and bounds that changed tenfold with the steps.
STEP_PIXELS = 0.5
STEP_TRANSLATION = 0.005


def hessian_steps(camera: CameraModel, n_intr: int) -> np.ndarray:
    """Steps (6 + n_intr,) of the joint Hessian's central differences (:data:`STEP_PIXELS`)."""
    fx = float(camera.intrinsics[0])
    corner = 0.5 * math.hypot(camera.width, camera.height)
    pose = [STEP_TRANSLATION] * 3 + [STEP_PIXELS / fx] * 3
    return np.array(pose + [STEP_PIXELS / corner, STEP_PIXELS, STEP_PIXELS][:n_intr])


def refined_camera(camera: CameraModel, theta) -> CameraModel:
    """``camera`` with the offset ``theta`` (``[lambda]`` or ``[lambda, dcx, dcy]``) applied."""
    theta = np.asarray(theta, dtype=np.float64).ravel()
    shift = (float(theta[1]), float(theta[2])) if theta.size == 3 else (0.0, 0.0)
    return offset_intrinsics(camera, focal_scale=math.exp(float(theta[0])), center_shift=shift)


def intrinsics_bounds(config: RefineConfig) -> list[tuple[float, float]]:
    """L-BFGS's box for ``theta``: the focal scale and principal point ranges of ``config``."""
    f = math.log1p(config.intrinsics_focal_range)
    c = config.intrinsics_center_range
    bounds = [(-f, f)]
    if INTRINSICS_MODES[config.intrinsics] == 3:
        bounds += [(-c, c), (-c, c)]
    return bounds


def check_pairs(pairs) -> None:
    """Refuse, in one line, a job whose intrinsics cannot be refined.

    Too few pairs, a rig, a camera without a focal length, or pairs of different cameras.
    """
    if len(pairs) < MIN_PAIRS:
        raise InputError(
            f"refine.intrinsics needs frames at several depths, at least {MIN_PAIRS} pairs: "
            f"the job has {len(pairs)}, and from one view a focal length cannot be told from "
            "the camera's forward position"
        )
    if any(getattr(p, "T_camera_rig", None) is not None for p in pairs):
        raise InputError("refine.intrinsics refines one camera: a rig's cameras are not supported")
    camera = pairs[0].camera
    if camera.model == "equirectangular":
        raise InputError(
            "refine.intrinsics: an equirectangular camera has no focal length or principal point"
        )
    if any(p.camera != camera for p in pairs):
        raise InputError("refine.intrinsics refines one camera: the pairs' cameras differ")


@dataclass
class IntrinsicsRefinement:
    """What the joint refinement of pose and intrinsics found, and whether it was kept.

    Attributes
    ----------
    mode : {"focal", "focal,center"}
    theta : ndarray of shape (1,) or (3,)
        The offset found: ``[lambda]`` or ``[lambda, dcx, dcy]`` (module docstring).
    given, camera : CameraModel
        The camera the job was given, and the one the result goes with (the refined one, or
        the given one when :attr:`refined` is False).
    refined : bool
        The frames told the intrinsics apart and the refined camera is the result's.
    reason : str
        Why the given intrinsics were kept (empty when refined).
    correlation : float
        Of ``lambda`` with the forward translation ``tz`` in the joint inverse Hessian.
    focal_bound_percent, center_bound_px : float
        95 % half-widths of the focal scale (per cent) and of the principal point (pixels, the
        larger of ``cx``'s and ``cy``'s; NaN with ``"focal"``).
    T_pose_only : ndarray of shape (4, 4)
        The pose fine registration found with the given intrinsics.
    T_joint : ndarray of shape (4, 4)
        The pose found with the intrinsics.
    nid_pose_only, nid_joint : float
    """

    mode: str
    theta: np.ndarray
    given: CameraModel
    camera: CameraModel
    refined: bool
    reason: str
    correlation: float
    focal_bound_percent: float
    center_bound_px: float
    T_pose_only: np.ndarray = field(repr=False)
    T_joint: np.ndarray = field(repr=False)
    nid_pose_only: float = math.nan
    nid_joint: float = math.nan

    @property
    def focal_scale(self) -> float:
        """The refined focal length over the given one."""
        return math.exp(float(self.theta[0]))

    @property
    def center_shift(self) -> tuple[float, float]:
        """The principal point's move, pixels (0, 0 with ``"focal"``)."""
        return (float(self.theta[1]), float(self.theta[2])) if self.theta.size == 3 else (0.0, 0.0)

    def summary(self) -> str:
        """One line: what was found, how well it is determined, whether it was kept."""
        found = f"focal x{self.focal_scale:.4f} (+-{self.focal_bound_percent:.2f} %)"
        if self.theta.size == 3:
            dx, dy = self.center_shift
            found += f", principal point {dx:+.1f}, {dy:+.1f} px (+-{self.center_bound_px:.1f} px)"
        found += f", focal/forward correlation {self.correlation:+.2f}"
        if self.refined:
            return f"intrinsics refined: {found}"
        return f"intrinsics kept as given: {self.reason} ({found})"

    def to_record(self) -> dict:
        """JSON-ready record (``nbcalib.calibration.intrinsics`` of ``calib.json``)."""
        from nbcalib.io.calib_json import values_from_T_camera_lidar

        def stored(T):  # T_lidar_camera [x, y, z, qx, qy, qz, qw], as calib.json's results
            return [float(v) for v in values_from_T_camera_lidar(T)]

        return {
            "mode": self.mode,
            "refined": self.refined,
            "reason": self.reason,
            "focal_scale": self.focal_scale,
            "center_shift_px": list(self.center_shift),
            "focal_bound_percent": self.focal_bound_percent,
            "center_bound_px": None if math.isnan(self.center_bound_px) else self.center_bound_px,
            "correlation_focal_forward": self.correlation,
            "given_camera": self.given.to_dict(),
            "camera": self.camera.to_dict(),
            "pose_only_T_lidar_camera": stored(self.T_pose_only),
            "joint_T_lidar_camera": stored(self.T_joint),
            "nid_pose_only": self.nid_pose_only,
            "nid_joint": self.nid_joint,
        }


def _pair_material(cost, T: np.ndarray, theta: np.ndarray, steps: np.ndarray):
    """A pair's joint gradient (6 + n,) and Hessian by central differences of gradients."""
    n = 6 + theta.size
    _, g0 = cost.value_and_grad(T, intrinsics=theta)
    H = np.empty((n, n))
    for j in range(n):
        d = np.zeros(n)
        d[j] = steps[j]
        _, g_plus = cost.value_and_grad(se3_exp(d[:6]) @ T, intrinsics=theta + d[6:])
        _, g_minus = cost.value_and_grad(se3_exp(-d[:6]) @ T, intrinsics=theta - d[6:])
        H[:, j] = (g_plus - g_minus) / (2.0 * steps[j])
    return g0, 0.5 * (H + H.T)


def _remeasured(cost, T: np.ndarray, H: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """``H`` with each non-positive curvature replaced by the cost's own rise along it.

    In the chart scaled by ``scale`` (the optimiser's units), along each eigenvector of
    non-positive eigenvalue, the second difference of the cost's values ``m = 1, 2, 4`` units
    out is taken and the first positive one kept (as the report does for the pose,
    :func:`nbcalib.report.uncertainty._remeasure_flat_directions`). The gradients' central
    differences are noisy along the directions where a rotation and a move of the principal
    point nearly undo each other; the values see their curvature.
    """
    Hs = H * scale[:, None] * scale[None, :]
    w, V = np.linalg.eigh(0.5 * (Hs + Hs.T))
    if np.all(w > 0.0):
        return H
    n_pose = 6
    value0 = cost.value(T, intrinsics=np.zeros(H.shape[0] - n_pose))
    for j in np.flatnonzero(w <= 0.0):
        for m in (1.0, 2.0, 4.0):
            x = m * V[:, j] * scale
            rise = (
                cost.value(se3_exp(x[:n_pose]) @ T, intrinsics=x[n_pose:])
                + cost.value(se3_exp(-x[:n_pose]) @ T, intrinsics=-x[n_pose:])
                - 2.0 * value0
            )
            if rise > 0.0:
                w[j] = rise / (m * m)
                break
    top = float(np.max(np.abs(w)))
    w = np.maximum(w, 1e-9 * top)  # a direction still flat: a huge but finite variance
    Hs = (V * w) @ V.T
    return Hs / (scale[:, None] * scale[None, :])


def identifiability(pairs, T: np.ndarray, theta, config: RefineConfig) -> dict:
    """How well the pairs separate the intrinsics from the pose at ``(T, theta)``.

    Each pair's cost is built at ``T`` with the camera at ``theta`` (its visible points, its
    regions), with the intrinsics' offset measured from there: its gradient and Hessian in
    ``[delta, theta]`` (central differences of the exact gradient). The summed Hessian's
    non-positive curvatures are measured again from the cost's values (:func:`_remeasured`).
    Returns ``correlation``, ``focal_bound_percent`` and ``center_bound_px`` (module
    docstring), the jackknife's covariance ``covariance`` (6 + n, 6 + n) of ``[delta,
    theta]`` (the minimum without pair ``k`` lies ``-(H (K - 1) / K)^-1 (g - g_k)`` away), and
    ``newton`` (6 + n,), one Newton step of the joint cost from ``(T, theta)``: where the
    joint minimum lies to second order (the report's check, :mod:`nbcalib.report.intrinsics`).
    """
    from nbcalib.registration.costs import build_cost
    from nbcalib.registration.optimize import LBFGS_INTRINSICS_SCALE, LBFGS_SCALE

    theta = np.asarray(theta, dtype=np.float64).ravel()
    camera = refined_camera(pairs[0].camera, theta)
    moved = [replace(p, camera=camera) for p in pairs]
    zero = np.zeros(theta.size)
    steps = hessian_steps(camera, theta.size)
    grads, hessians = [], []
    for pair in moved:
        cost, _ = build_cost([pair], T, config, n_pairs=len(moved))
        g, H = _pair_material(cost, T, zero, steps)
        grads.append(g)
        hessians.append(H)
    whole, _ = build_cost(moved, T, config)
    scale = np.concatenate([LBFGS_SCALE, LBFGS_INTRINSICS_SCALE[: theta.size]])
    H_all = _remeasured(whole, T, np.sum(hessians, axis=0), scale)
    C = np.linalg.inv(H_all)
    correlation = float(np.clip(C[2, 6] / math.sqrt(C[2, 2] * C[6, 6]), -1.0, 1.0))
    K = len(moved)
    g_all = np.sum(grads, axis=0)
    steps = np.array([-(K / (K - 1)) * (C @ (g_all - g)) for g in grads])
    d = steps - steps.mean(axis=0)
    cov = (K - 1) / K * (d.T @ d)
    half = 1.96 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    focal = 100.0 * math.expm1(min(float(half[6]), math.log(2.0)))  # at most 100 %
    center = float(max(half[7], half[8])) if theta.size == 3 else math.nan
    return {
        "correlation": correlation,
        "focal_bound_percent": focal,
        "center_bound_px": center,
        "covariance": cov,
        "newton": -(C @ g_all),
    }
