"""Fine registration (paper section III-E): hidden-point removal, then NID minimisation, repeated.

Each outer iteration

1. removes, per pair, the LiDAR points the camera cannot see from the current pose (a z-buffer
   at the camera's resolution; points more than ``depth_margin`` behind the nearest point in
   their pixel, or ``window`` pixels around it, are hidden);
2. minimises the NID summed over the pairs in a trust box around the current pose (L-BFGS on the
   B-spline NID with its exact gradient, or Nelder-Mead on the hard-binned NID as the paper;
   the default ``optimizer="hybrid"`` runs the whole loop with Nelder-Mead, then again at full
   resolution with L-BFGS from its result);
   the cost is chosen by ``cost`` in :mod:`nbcalib.registration.costs`: by default the
   regional NID (one joint histogram per image region of ``region_points`` to twice as many
   points, the regions cut at the pose each outer iteration starts from); ``"nid"`` is the NID
   of the whole pair, conditioned on surface orientation when ``orientation_classes``;
3. stops when the pose moved less than ``converge_translation`` and ``converge_rotation_deg``.

The whole run stays in a trust region around its initial guess (``trust_translation``,
``trust_rotation_deg``; :mod:`nbcalib.registration.trust`): every inner minimisation returns a
pose inside it, and :attr:`RefineResult.at_trust_boundary` says when the result ended on its
edge (its optimum may lie beyond).

The whole loop runs coarse to fine over an image pyramid (``pyramid_levels``): at level ``k`` the
image is averaged over ``2^k x 2^k`` blocks, re-equalised, and the camera's focal lengths and
principal point are scaled to match, so the B-spline NID spans ``4 * 2^k`` full-resolution pixels.
The coarse levels widen the basin of convergence (a 1.5 degree error is ~30 pixels of a
1280 x 960 image); the finest level sets the accuracy. Hidden-point removal always runs at the
full resolution.

The reference toolbox stops on 0.1 m / 0.5 degree changes; that lets a run stop 5 cm from where
the next iteration would go, so nbcalib's defaults are 1 mm / 0.01 degree.

Example
-------
>>> pairs = [RegistrationPair(camera, image, points_lidar, intensities)]   # doctest: +SKIP
>>> result = refine(pairs, T_camera_lidar_init)                              # doctest: +SKIP
>>> result.T_camera_lidar, result.history[-1].nid                            # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from nbcalib.errors import InputError
from nbcalib.progress import Progress
from nbcalib.registration.config import INTRINSICS_MODES, RefineConfig
from nbcalib.registration.costs import build_cost
from nbcalib.registration.optimize import InnerResult, minimize_lbfgs, minimize_nelder_mead
from nbcalib.registration.pair import (
    RegistrationPair,
    downscale_camera,
    downscale_image,
    visible_subset,
)
from nbcalib.registration.trust import TrustRegion, on_trust_boundary
from nbcalib.transforms import invert_T, pose_error, validate_T

__all__ = [
    "OuterIteration",
    "RefineConfig",
    "RefineResult",
    "RegistrationPair",
    "build_cost",
    "downscale_camera",
    "downscale_image",
    "refine",
    "visible_subset",
]


@dataclass
class OuterIteration:
    """What one outer iteration did; ``T_camera_lidar`` is the pose it ended at."""

    nid: float
    nid_start: float
    visible_points: list[int]
    iterations: int
    evaluations: int
    translation_change: float
    rotation_change_deg: float
    seconds: float
    message: str
    level: int = 0
    optimizer: str = "lbfgs"
    T_camera_lidar: np.ndarray | None = field(default=None, repr=False)


@dataclass
class RefineResult:
    """Result of :func:`refine`: the pose, the per-iteration history and totals.

    ``stopped`` says why a run was cut short (empty when it converged or used its iterations;
    no setting cuts a run short now: the trust region bounds it instead). ``T_init`` is the
    initial guess and ``trust_translation`` / ``trust_rotation_deg`` the trust region around it
    that the run stayed in (:mod:`nbcalib.registration.trust`).
    """

    T_camera_lidar: np.ndarray
    history: list[OuterIteration] = field(default_factory=list)
    converged: bool = False
    stopped: str = ""
    T_init: np.ndarray | None = None
    trust_translation: float | None = None
    trust_rotation_deg: float | None = None
    #: With ``refine.intrinsics``: the joint refinement of pose and intrinsics
    #: (:class:`~nbcalib.registration.intrinsics.IntrinsicsRefinement`); None otherwise.
    intrinsics: object = None

    @property
    def camera(self):
        """The camera the result goes with when the intrinsics were refined (else None)."""
        return None if self.intrinsics is None else self.intrinsics.camera

    @property
    def moved(self) -> tuple[float, float]:
        """Distance of the result from ``T_init``: metres (camera centre) and degrees."""
        if self.T_init is None:
            return math.nan, math.nan
        dt, dr = pose_error(invert_T(self.T_camera_lidar), invert_T(self.T_init))
        return float(dt), float(dr)

    @property
    def moved_translation(self) -> float:
        """How far the camera centre moved from the start, metres (LiDAR frame)."""
        return self.moved[0]

    @property
    def moved_rotation_deg(self) -> float:
        """How far the rotation moved from the start, degrees."""
        return self.moved[1]

    @property
    def at_trust_boundary(self) -> bool:
        """The result lies on the edge of the trust region (its optimum may lie beyond)."""
        if self.T_init is None or self.trust_translation is None:
            return False
        region = (self.trust_translation, self.trust_rotation_deg)
        return on_trust_boundary(self.moved, region)

    @property
    def nid(self) -> float:
        """Final summed NID."""
        return self.history[-1].nid if self.history else math.nan

    @property
    def evaluations(self) -> int:
        """Cost evaluations over all outer iterations."""
        return sum(h.evaluations for h in self.history)

    @property
    def iterations(self) -> int:
        """Inner iterations over all outer iterations."""
        return sum(h.iterations for h in self.history)


def refine(
    pairs: Sequence[RegistrationPair],
    T_camera_lidar_init,
    config: RefineConfig | None = None,
    *,
    progress: bool | Callable[[int, OuterIteration], None] | None = None,
) -> RefineResult:
    """Refine ``T_camera_lidar`` by NID minimisation with hidden-point removal.

    Parameters
    ----------
    pairs : sequence of RegistrationPair
        One or more LiDAR-camera pairs that share the extrinsic.
    T_camera_lidar_init : array_like of shape (4, 4)
        Initial guess, ``p_camera = T_camera_lidar @ p_lidar``.
    config : RefineConfig, optional
    progress : bool or callable, optional
        ``True`` for a progress display (:class:`nbcalib.progress.Progress`: a bar on a
        terminal, step lines in a log, nothing when the ``nbcalib`` logger is quiet), or a
        callback ``progress(outer_index, OuterIteration)`` after each outer iteration.

    Returns
    -------
    RefineResult
    """
    config = config or RefineConfig()
    if not pairs:
        raise ValueError("refine needs at least one LiDAR-camera pair")
    if config.intrinsics is not None:
        from nbcalib.registration.intrinsics import check_pairs

        check_pairs(pairs)  # before any work
    T = validate_T(np.asarray(T_camera_lidar_init, dtype=np.float64), "T_camera_lidar_init")
    result = RefineResult(
        T.copy(),
        T_init=T.copy(),
        trust_translation=config.trust_translation,
        trust_rotation_deg=config.trust_rotation_deg,
    )
    region = TrustRegion(T, config.trust_translation, config.trust_rotation_deg)
    if config.optimizer == "hybrid":
        # Nelder-Mead on the hard NID over the pyramid finds the basin; L-BFGS on the smooth
        # NID at full resolution then polishes (docs/BENCHMARKS.md, "hybrid optimiser")
        stages = [
            replace(config, optimizer="nelder_mead", intrinsics=None),
            replace(config, optimizer="lbfgs", pyramid_levels=0),
        ]
    else:
        stages = [config]
    with Progress(label="refine", enabled=progress is True) as display:

        def report(outer: int, step: OuterIteration) -> None:
            if callable(progress):
                progress(outer, step)
            display.update(what=f"outer iterations (level {step.level}, NID {step.nid:.5f})")

        for stage in stages:
            _run_levels(pairs, region, stage, result, report)
        if config.intrinsics is not None:
            _refine_intrinsics(pairs, region, config, result, report)
    return result


def _refine_intrinsics(
    pairs, region: TrustRegion, config: RefineConfig, result: RefineResult, progress
) -> None:
    """Pose and intrinsics together from the pose's result: L-BFGS at full resolution.

    Each outer iteration sees the pairs through the camera at the intrinsics it starts from
    (hidden points, regions), and minimises over the pose and their offset from there. Then
    :func:`~nbcalib.registration.intrinsics.identifiability` decides whether the refined
    intrinsics are kept (:attr:`RefineResult.intrinsics`).
    """
    from nbcalib.registration import intrinsics as intr

    given = pairs[0].camera
    T_pose, nid_pose = result.T_camera_lidar.copy(), result.nid
    theta = np.zeros(INTRINSICS_MODES[config.intrinsics])
    stage = replace(config, optimizer="lbfgs", pyramid_levels=0)
    bounds = intr.intrinsics_bounds(config)
    max_rot = math.radians(config.max_rotation_deg)
    T, joint = T_pose, []
    for _ in range(config.max_outer):
        moved = [replace(p, camera=intr.refined_camera(given, theta)) for p in pairs]
        step, T_new, theta_new = _outer_iteration(
            moved, T, stage, 0, max_rot, region, intrinsics=(theta, bounds)
        )
        step.optimizer = f"lbfgs+{config.intrinsics}"
        shift = np.abs(theta_new - theta)
        T, theta = T_new, theta_new
        joint.append(step)
        progress(len(result.history) + len(joint) - 1, step)
        if (
            step.translation_change < config.converge_translation
            and step.rotation_change_deg < config.converge_rotation_deg
            and shift[0] < 1e-4
            and (shift.size == 1 or shift[1:].max() < 0.05)
        ):
            break
    found = intr.identifiability(pairs, T, theta, config)
    reasons = []
    if found["focal_bound_percent"] > 100 * config.intrinsics_max_focal_bound:
        reasons.append(
            f"the frames fix the focal length only to +-{found['focal_bound_percent']:.2f} % "
            f"(needed: {100 * config.intrinsics_max_focal_bound:g} %)"
        )
    if theta.size == 3 and found["center_bound_px"] > config.intrinsics_max_center_bound:
        reasons.append(
            f"the principal point only to +-{found['center_bound_px']:.1f} px "
            f"(needed: {config.intrinsics_max_center_bound:g} px)"
        )
    refined = not reasons
    camera = intr.refined_camera(given, theta)
    result.intrinsics = intr.IntrinsicsRefinement(
        mode=config.intrinsics,
        theta=theta,
        given=given,
        camera=camera if refined else given,
        refined=refined,
        reason="; ".join(reasons),
        correlation=found["correlation"],
        focal_bound_percent=found["focal_bound_percent"],
        center_bound_px=found["center_bound_px"],
        T_pose_only=T_pose,
        T_joint=T.copy(),
        nid_pose_only=nid_pose,
        nid_joint=joint[-1].nid,
    )
    if refined:
        result.history.extend(joint)
        result.T_camera_lidar = T.copy()


def _run_levels(
    pairs, region: TrustRegion, config: RefineConfig, result: RefineResult, progress
) -> None:
    """Outer iterations from ``result.T_camera_lidar``, coarse to fine, inside ``region``.

    ``region`` is the trust region around the caller's initial guess: every outer iteration's
    pose lies in it (the inner minimisations return only poses inside), so the run may slide
    along its edge but never leaves it.
    """
    T = result.T_camera_lidar.copy()
    max_rot = math.radians(config.max_rotation_deg)
    for level in range(_usable_levels(pairs, config), -1, -1):
        # coarse levels only bring the pose into the finest level's basin: looser stop
        scale = 2**level
        for _ in range(config.max_outer):
            step, T_new = _outer_iteration(pairs, T, config, level, max_rot, region)
            dt, dr = step.translation_change, step.rotation_change_deg
            outer = len(result.history)
            result.history.append(step)
            T = T_new
            result.T_camera_lidar = T.copy()
            progress(outer, step)
            if (
                dt < scale * config.converge_translation
                and dr < scale * config.converge_rotation_deg
            ):
                result.converged = level == 0
                break
        else:
            result.converged = False


def _usable_levels(pairs: Sequence[RegistrationPair], config: RefineConfig) -> int:
    """Pyramid levels whose images keep at least ``min_pyramid_size`` pixels on the short side."""
    shortest = min(min(p.camera.width, p.camera.height) for p in pairs)
    levels = 0
    while levels < config.pyramid_levels and shortest >> (levels + 1) >= config.min_pyramid_size:
        levels += 1
    return levels


def _outer_iteration(
    pairs,
    T,
    config: RefineConfig,
    level: int,
    max_rot: float,
    region: TrustRegion | None = None,
    *,
    intrinsics=None,
):
    """Hidden-point removal at ``T``, then one inner minimisation at pyramid ``level``.

    The minimisation returns a pose inside ``region`` (the run's trust region) when given.
    ``intrinsics``: ``(theta, bounds)`` to refine the intrinsics with the pose by L-BFGS, the
    pairs' camera being at ``theta`` already; then returns ``(step, T, theta)``.
    """
    t0 = time.perf_counter()
    cost, counts = build_cost(pairs, T, config, level=level)
    if sum(counts) < config.min_visible_points:
        raise InputError(
            f"only {sum(counts)} LiDAR points fall into the image(s) at the pose being refined "
            f"(need {config.min_visible_points}): the start does not look at the cloud, or the "
            "camera does not fit the images"
        )
    start_value = cost.value(T)
    inner: InnerResult
    if intrinsics is not None:
        theta0, bounds = intrinsics
        inner = minimize_lbfgs(
            lambda T_, theta: cost.value_and_grad(T_, intrinsics=theta - theta0),
            T,
            max_translation=config.max_translation,
            max_rotation=max_rot,
            max_iterations=config.max_inner,
            ftol=config.lbfgs_ftol,
            trust_region=region,
            intrinsics=theta0,
            intrinsics_bounds=bounds,
        )
    elif config.optimizer == "lbfgs":
        inner = minimize_lbfgs(
            cost.value_and_grad,
            T,
            max_translation=config.max_translation,
            max_rotation=max_rot,
            max_iterations=config.max_inner,
            ftol=config.lbfgs_ftol,
            trust_region=region,
        )
    else:
        inner = minimize_nelder_mead(
            cost.value,
            T,
            init_step=config.nelder_mead_init_step * 2**level,
            max_translation=config.max_translation,
            max_rotation=max_rot,
            max_evaluations=40 * config.max_inner,
            xatol=config.nelder_mead_xatol * 2**level,
            fatol=config.nelder_mead_fatol,
            trust_region=region,
        )
    T_new = inner.T_camera_lidar
    theta_new = None if intrinsics is None else inner.intrinsics
    if inner.value > start_value:  # never accept a worse pose
        T_new, inner.value = T, start_value
        theta_new = None if intrinsics is None else intrinsics[0]
    dt, dr = pose_error(invert_T(T_new), invert_T(T))
    step = OuterIteration(
        nid=inner.value,
        nid_start=start_value,
        visible_points=counts,
        iterations=inner.iterations,
        evaluations=inner.evaluations,
        translation_change=float(dt),
        rotation_change_deg=float(dr),
        seconds=time.perf_counter() - t0,
        message=inner.message,
        level=level,
        optimizer=config.optimizer,
        T_camera_lidar=T_new.copy(),
    )
    if intrinsics is not None:
        return step, T_new, theta_new
    return step, T_new
