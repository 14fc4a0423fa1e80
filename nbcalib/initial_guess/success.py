"""Whether an initial guess can be trusted: enough inliers, distinct from rival poses, precise.

:class:`InitialGuess` is what :func:`~nbcalib.initial_guess.estimate.estimate_initial_guess`
returns. The result says how far it can be trusted: the inliers after LM (reprojection error
below the RANSAC threshold), their RMS error and ``success``: at least ``min_inliers`` inliers,
and the answer must be *distinct*: it must explain ``min_distinctiveness`` (2) times more
correspondences than the best pose with a rotation more than 5 degrees away explains *of the
ones the answer leaves unexplained*. Matches that are mostly wrong support many poses about
equally; on real KITTI frames 12-14 inliers of 92-149 wrong matches passed the count alone
(docs/BENCHMARKS.md). Both counts are full-pose reprojection inliers: the other poses are the
best few RANSAC rotations beyond 5 degrees, each with the translation that explains most for it
(:func:`translation_ransac`). Only the answer's outliers may support the other pose, since a
pose 5 degrees away also explains many of the answer's own inliers when they are far away or
the threshold is wide: counted over all correspondences, a correct synthetic guess (0.28 deg,
1.2 cm; 415 inliers) met a runner-up of 249 and was refused. Counted in
rotation-only RANSAC's own measure instead, near points (a room, 1-10 m, the camera up to 30 cm
from the LiDAR) give rotations several degrees off the answer support through their parallax,
and 28 % of good room guesses were called not distinct.

And the answer must be *precise*: ``precision_scale`` (8) times the 95 % bounds its inliers'
noise leaves (:func:`pose_uncertainty`) must lie within the 1 deg / 0.5 m that fine registration
starts from. Matches share errors their noise does not show (a rendered LiDAR image against a
photograph): guesses were 2-9 times their bound off, one 16 times (docs/BENCHMARKS.md 11).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.initial_guess.lm import LMResult, reprojection_residuals
from nbcalib.initial_guess.ransac import RotationRansacResult
from nbcalib.initial_guess.translation import translation_ransac
from nbcalib.metrics import interval_quantiles

__all__ = ["DISTINCT_ROTATION_DEG", "InitialGuess", "pose_uncertainty"]

#: Rotations further apart than this (degrees) are different answers for the success test.
DISTINCT_ROTATION_DEG = 5.0


@dataclass(frozen=True)
class InitialGuess:
    """An initial ``T_camera_lidar`` and how well the correspondences support it.

    Attributes
    ----------
    T_camera_lidar : ndarray of shape (4, 4), float64
        ``p_camera = T_camera_lidar @ p_lidar``.
    inliers : ndarray of shape (M,), bool
        Correspondences whose final reprojection error is below ``threshold``.
    errors : ndarray of shape (M,), float64
        Final reprojection errors, pixels (inf where the point projects invalidly).
    rms_px : float
        RMS reprojection error over the inliers, pixels (NaN without inliers).
    success : bool
        At least ``min_inliers`` inliers, distinct from rival poses and :attr:`precise`: the
        pipeline may trust the guess (:attr:`failure` says why not).
    threshold : float
        Inlier threshold, pixels (the RANSAC threshold).
    min_inliers : int
        Inliers needed for ``success``.
    ransac : RotationRansacResult
        The rotation-only RANSAC step.
    refinement : LMResult
        The LM step (paper Eq. 1 over all correspondences, before the polish).
    T_camera_lidar_start : ndarray of shape (4, 4), float64
        Where LM started (for the winning candidate).
    candidate : int
        Rank of the winning RANSAC hypothesis among the refined ones (0: the RANSAC winner).
    support : int
        Correspondences the final pose explains (its inliers).
    runner_up : int
        Most correspondences a pose whose rotation is more than :data:`DISTINCT_ROTATION_DEG`
        from the final one explains among those the final pose does not (the best few such
        RANSAC rotations, each with its best translation): the evidence of the best *other*
        answer the data offer.
    min_distinctiveness : float
        ``support / runner_up`` needed for ``success``.
    runner_up_shared : int
        The same rival poses' most correspondences among *all* of them (the answer's inliers
        included).
    min_shared_distinctiveness : float
        ``support / runner_up_shared`` needed for ``success``.
    bound_m, bound_deg : float
        95 % bounds on the pose's error from its inliers' reprojections
        (:func:`pose_uncertainty`): what their noise leaves, not their shared error.
    precision_scale : float
        ``success`` needs ``precision_scale`` times these bounds within ``max_error_m`` and
        ``max_error_deg`` (0: no such test).
    max_error_m, max_error_deg : float
        How far a start may be from the truth for fine registration (the paper: 0.5 m, 1 deg).
    """

    T_camera_lidar: np.ndarray
    inliers: np.ndarray
    errors: np.ndarray
    rms_px: float
    success: bool
    threshold: float
    min_inliers: int
    ransac: RotationRansacResult
    refinement: LMResult
    T_camera_lidar_start: np.ndarray
    candidate: int
    support: int = 0
    runner_up: int = 0
    min_distinctiveness: float = 0.0
    runner_up_shared: int = 0
    min_shared_distinctiveness: float = 0.0
    bound_m: float = math.inf
    bound_deg: float = math.inf
    precision_scale: float = 0.0
    max_error_m: float = math.inf
    max_error_deg: float = math.inf

    @property
    def found(self) -> bool:
        """Enough inliers and distinct from rival poses: ``success`` without :attr:`precise`.

        What matching asks of an attempt: did its matches find the pose?
        """
        return (
            self.n_inliers >= self.min_inliers
            and self.support >= self.min_distinctiveness * max(self.runner_up, 1)
            and self.support >= self.min_shared_distinctiveness * max(self.runner_up_shared, 1)
        )

    @property
    def precise(self) -> bool:
        """``precision_scale`` times the bounds within ``max_error_m`` and ``max_error_deg``."""
        k = self.precision_scale
        return k <= 0 or (
            k * self.bound_m <= self.max_error_m and k * self.bound_deg <= self.max_error_deg
        )

    @property
    def distinctiveness(self) -> float:
        """How many times more correspondences the answer explains than the best other rotation."""
        return self.support / max(self.runner_up, 1)

    @property
    def failure(self) -> str:
        """Why ``success`` is False ("" when it is True)."""
        if self.n_inliers < self.min_inliers:
            return f"fewer than {self.min_inliers} inliers"
        if self.support < self.min_shared_distinctiveness * max(self.runner_up_shared, 1):
            return (
                f"not distinct: a pose rotated {DISTINCT_ROTATION_DEG:g}+ deg away explains "
                f"{self.runner_up_shared} correspondences, this one {self.support} "
                f"(need {self.min_shared_distinctiveness:g}x)"
            )
        if self.distinctiveness < self.min_distinctiveness:
            return (
                f"not distinct: a pose rotated {DISTINCT_ROTATION_DEG:g}+ deg away explains "
                f"{self.runner_up} of the correspondences this one leaves out, this one "
                f"{self.support} (need {self.min_distinctiveness:g}x)"
            )
        if not self.precise:
            k = self.precision_scale
            return (
                f"imprecise: its inliers bound it to {100 * self.bound_m:.1f} cm / "
                f"{self.bound_deg:.2f} deg, times {k:g} for the matches' shared error "
                f"{100 * k * self.bound_m:.0f} cm / {k * self.bound_deg:.1f} deg, more than the "
                f"{self.max_error_m:g} m / {self.max_error_deg:g} deg fine registration starts from"
            )
        return ""

    @property
    def n_inliers(self) -> int:
        """Number of inliers after LM."""
        return int(np.count_nonzero(self.inliers))

    @property
    def n_correspondences(self) -> int:
        """Number of correspondences given."""
        return len(self.inliers)

    def summary(self) -> str:
        """One line: correspondences, RANSAC and final inliers, RMS, success."""
        verdict = "ok" if self.success else f"FAILED ({self.failure})"
        rms = f"{self.rms_px:.2f} px" if math.isfinite(self.rms_px) else "n/a"
        return (
            f"{self.n_correspondences} correspondences, RANSAC inliers {self.ransac.n_inliers}, "
            f"final inliers {self.n_inliers} (< {self.threshold:g} px), RMS {rms}, "
            f"{self.distinctiveness:.1f}x the best other rotation, noise bounds "
            f"{100 * self.bound_m:.1f} cm / {self.bound_deg:.2f} deg: {verdict}"
        )


def pose_uncertainty(
    camera: CameraModel, T_camera_lidar, uv_camera, points_lidar, confidence: float = 0.95
) -> tuple[float, float]:
    """Bounds on a pose's error from the reprojections of its inliers, at ``confidence``.

    The least-squares covariance ``s^2 (J^T J)^-1`` of ``delta = [v, omega]`` (the left
    perturbation of ``T_camera_lidar``; ``|v|`` is the camera centre's displacement), ``J`` the
    reprojection Jacobian of the given correspondences and ``s^2`` their residuals' variance
    (``2M - 6`` degrees of freedom); then the ``confidence`` quantiles of ``|v|`` and
    ``|omega|`` (:func:`nbcalib.metrics.interval_quantiles`). It sees the noise of the
    keypoints and how the points' spread over the image and in depth constrains each
    direction (points on one wall at one depth leave rotation and translation coupled); not
    matches that are wrong in the same way.

    Returns
    -------
    translation : float
        Metres (inf with fewer than 4 usable correspondences or a singular geometry).
    rotation : float
        Degrees.
    """
    r, J, valid = reprojection_residuals(camera, T_camera_lidar, uv_camera, points_lidar)
    ok = valid & np.isfinite(r).all(axis=1) & np.isfinite(J).all(axis=(1, 2))
    if np.count_nonzero(ok) < 4:
        return math.inf, math.inf
    Jm, rm = J[ok].reshape(-1, 6), r[ok].reshape(-1)
    information = Jm.T @ Jm
    w = np.linalg.eigvalsh(information)
    if w[0] <= 1e-12 * max(w[-1], 1e-300):
        return math.inf, math.inf
    covariance = float(rm @ rm) / max(rm.size - 6, 1) * np.linalg.inv(information)
    _, t_bound, r_bound = interval_quantiles(covariance, confidence)
    return float(t_bound), math.degrees(r_bound)


#: RANSAC rotations beyond :data:`DISTINCT_ROTATION_DEG` tried as the runner-up answer.
_RUNNER_UP_CANDIDATES = 3


def _runner_up(
    camera,
    ransac: RotationRansacResult,
    R_final,
    uv,
    points,
    bearings,
    free,
    *,
    threshold,
    seed,
    iterations,
    origin=None,
) -> tuple[int, int]:
    """Most correspondences a pose rotated more than ``DISTINCT_ROTATION_DEG`` away explains.

    The best :data:`_RUNNER_UP_CANDIDATES` RANSAC rotations that far away (and at least
    1 degree from each other) each get the translation that explains most correspondences
    (:func:`translation_ransac`), in the same full-pose measure as the final pose's inliers:
    once among the correspondences ``free`` (those the final pose leaves unexplained, the
    rival's own evidence) and once among all of them (evidence shared with the answer counted
    too). Returns the two maxima, (own, shared).
    """
    others = ransac.ranked_hypotheses(
        _RUNNER_UP_CANDIDATES, min_inliers=1, away_from=R_final, away_deg=DISTINCT_ROTATION_DEG
    )
    own = shared = 0
    n_free = int(np.count_nonzero(free))
    for _, _, R in others:
        _, n = translation_ransac(
            camera,
            R,
            uv,
            points,
            bearings,
            threshold=threshold,
            iterations=iterations,
            seed=seed,
            origin=origin,
        )
        shared = max(shared, n)
        if n_free >= 2:
            _, n = translation_ransac(
                camera,
                R,
                uv[free],
                points[free],
                bearings[free],
                threshold=threshold,
                iterations=iterations,
                seed=seed,
                origin=origin,
            )
        else:
            n = n_free
        own = max(own, n)
    return own, shared
