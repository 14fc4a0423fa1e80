"""The initial guess from 2D-3D correspondences: rotation-only RANSAC, then robust LM.

Paper section III-D: :func:`~nbcalib.initial_guess.ransac.estimate_rotation_ransac` finds the
rotation supported by the most correspondences (translation ignored), and
:func:`~nbcalib.initial_guess.lm.refine_pose_lm` minimises the Cauchy-robustified
reprojection error of all correspondences over the full pose, starting from that rotation.

nbcalib adds four things to the reference toolbox's procedure (measured in docs/BENCHMARKS.md;
``candidates=1, local_optimization=False, initial_translation="zero", polish=False`` switches
them off):

- **candidates**: near points break the far-field assumption, so the true rotation is not always
  RANSAC's winner; the best few distinct hypotheses are refined and the pose with the most
  inliers after LM wins;
- **local optimisation**: LM first fits a hypothesis's own RANSAC inliers, then all
  correspondences, then refits the current inliers and all again while the inlier set changes
  (the last fit is always Eq. 1 over all correspondences);
- **start translation** ``"bearing"``: the translation that best explains the RANSAC inliers'
  rays for the RANSAC rotation (:func:`translation_from_bearings`), instead of zero;
- **polish**: Eq. 1 over *all* correspondences is what the paper minimises, but with most
  matches wrong (60-87 % on the synthetic pairs) the outliers' pull on a weakly constrained
  direction moves its minimum: from the truth itself LM walked 1.3 m along the camera axis on a
  street pair whose points lie 8-50 m away, and 1.1 degrees on a room pair that sees one wall.
  So the winner is polished: a translation-only RANSAC (two correspondences fix ``t`` for the
  found rotation) replaces ``t`` when it explains more correspondences, then LM refits the
  inliers with a narrow kernel (``polish_kernel_width``) while the inlier set changes (at most
  3 times), like the final least-squares step of any RANSAC.

Optional per-correspondence ``weights`` (the matcher's confidences) scale the terms of Eq. 1.

The result says how far it can be trusted: the inliers after LM (reprojection error below the
RANSAC threshold), their RMS error and ``success``: at least ``min_inliers`` inliers, and the
answer must be *distinct*: it must explain ``min_distinctiveness`` (2) times more
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
import operator
from dataclasses import dataclass, replace

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.initial_guess.config import INITIAL_TRANSLATIONS, InitialGuessConfig
from nbcalib.initial_guess.lm import (
    LMResult,
    refine_pose_lm,
    reprojection_errors,
    reprojection_residuals,
)
from nbcalib.initial_guess.ransac import (
    RotationRansacResult,
    estimate_rotation_ransac,
    usable_correspondences,
)
from nbcalib.metrics import interval_quantiles
from nbcalib.transforms import make_T

__all__ = [
    "INITIAL_TRANSLATIONS",
    "MIN_CORRESPONDENCES",
    "InitialGuess",
    "estimate_initial_guess",
    "pose_uncertainty",
    "translation_from_bearings",
    "translation_ransac",
]

#: Rounds of "fit the inliers, then all" after the first fit (local optimisation).
_LO_ROUNDS = 3

#: Candidates after the first are skipped once the best final inlier count is at least this
#: many times the next candidate's RANSAC inlier count (and at least ``min_inliers``).
_EARLY_STOP_RATIO = 3

#: Rounds of "fit the inliers" in the polish step.
_POLISH_ROUNDS = 3

#: Rotations further apart than this (degrees) are different answers for the success test.
DISTINCT_ROTATION_DEG = 5.0

#: Fewest correspondences the estimate accepts (a pose has 6 degrees of freedom, each
#: correspondence gives 2 equations; the reference's manual tool asks for 3 as well).
MIN_CORRESPONDENCES = 3


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


def translation_from_bearings(
    R_camera_lidar, bearings_camera, points_lidar, *, max_norm: float | None = None
) -> np.ndarray:
    """Translation that best lines up rotated points with camera bearings, for a fixed rotation.

    Each correspondence asks ``b_j x (R p_j + t) = 0`` (the camera-frame point lies on the
    keypoint's ray); divided by ``|p_j|`` this is the sine of the angle between the ray and the
    point. The least-squares ``t`` of these linear equations is returned; rays that are all
    parallel leave ``t`` along them undetermined, and the minimum-norm solution is taken.

    Parameters
    ----------
    R_camera_lidar : array_like of shape (3, 3)
        Rotation of ``T_camera_lidar``.
    bearings_camera : array_like of shape (K, 3)
        Unit camera bearings of the keypoints.
    points_lidar : array_like of shape (K, 3)
        Their 3-D points in the LiDAR frame, metres (non-zero).
    max_norm : float, optional
        Return zero translation when the solution is longer than this (metres): an unreliable
        solve (e.g. an outlier among few correspondences) is worse than the reference's zero.

    Returns
    -------
    ndarray of shape (3,), float64
        ``t`` of ``T_camera_lidar``, metres.
    """
    R = np.asarray(R_camera_lidar, dtype=np.float64)
    b = np.asarray(bearings_camera, dtype=np.float64)
    p = np.asarray(points_lidar, dtype=np.float64)
    if len(b) < 2:
        return np.zeros(3)
    q = p @ R.T
    scale = 1.0 / np.linalg.norm(p, axis=1)
    # [b]x t = -[b]x q, each row scaled by 1 / |p|
    bx = np.zeros((len(b), 3, 3))
    bx[:, 0, 1], bx[:, 0, 2] = -b[:, 2], b[:, 1]
    bx[:, 1, 0], bx[:, 1, 2] = b[:, 2], -b[:, 0]
    bx[:, 2, 0], bx[:, 2, 1] = -b[:, 1], b[:, 0]
    A = (bx * scale[:, None, None]).reshape(-1, 3)
    rhs = (-np.cross(b, q) * scale[:, None]).reshape(-1)
    t, *_ = np.linalg.lstsq(A, rhs, rcond=1e-9)
    if not np.all(np.isfinite(t)) or (max_norm is not None and np.linalg.norm(t) > max_norm):
        return np.zeros(3)
    return t


def _refine_from(
    camera,
    uv,
    points,
    bearings_camera,
    R,
    support,
    *,
    initial_translation,
    max_initial_translation,
    threshold,
    robust_kernel_width,
    local_optimization,
    max_lm_iterations,
    weights,
):
    """LM from one rotation hypothesis; returns (start pose, LM result of the last stage)."""
    t = np.zeros(3)
    if initial_translation == "bearing":
        t = translation_from_bearings(
            R, bearings_camera[support], points[support], max_norm=max_initial_translation
        )
    T_start = make_T(R, t)

    def lm(mask, T):
        return refine_pose_lm(
            camera,
            uv[mask],
            points[mask],
            T,
            robust_kernel_width=robust_kernel_width,
            weights=weights[mask],
            max_iterations=max_lm_iterations,
        )

    everything = np.ones(len(uv), dtype=bool)
    T = T_start
    if local_optimization and np.count_nonzero(support) >= MIN_CORRESPONDENCES:
        T = lm(support, T).T_camera_lidar
    result = lm(everything, T)
    previous = support
    for _ in range(_LO_ROUNDS if local_optimization else 0):
        current = result.errors < threshold
        if np.count_nonzero(current) < MIN_CORRESPONDENCES or np.array_equal(current, previous):
            break
        previous = current
        T = lm(current, result.T_camera_lidar).T_camera_lidar
        result = lm(everything, T)
    return T_start, result


#: Translation hypotheses scored per call of the projection (memory: 64 x M points).
_HYPOTHESES_PER_BATCH = 64


def _inlier_counts(camera, R, translations, uv, points, threshold) -> np.ndarray:
    """Per translation ``t`` (rows): correspondences ``(R, t)`` reprojects within ``threshold``."""
    ts = np.asarray(translations, dtype=np.float64).reshape(-1, 3)
    q = points @ R.T
    proj, valid = camera.project((q[None, :, :] + ts[:, None, :]).reshape(-1, 3))
    diff = proj.reshape(len(ts), -1, 2) - uv[None, :, :]
    error2 = np.einsum("hmi,hmi->hm", diff, diff)
    return np.count_nonzero(valid.reshape(len(ts), -1) & (error2 < threshold * threshold), axis=1)


def _translations_of_pairs(R, bearings, points) -> np.ndarray:
    """:func:`translation_from_bearings` of many 2-correspondence samples at once.

    ``bearings`` and ``points`` are (S, 2, 3); the same minimum-norm least squares (singular
    values below ``1e-9`` of the largest dropped, as ``lstsq`` with ``rcond=1e-9``), by a
    batched SVD. Non-finite solutions become zero, as there.
    """
    b = bearings
    scale = 1.0 / np.linalg.norm(points, axis=2)  # (S, 2)
    q = points @ R.T
    bx = np.zeros((*b.shape[:2], 3, 3))
    bx[..., 0, 1], bx[..., 0, 2] = -b[..., 2], b[..., 1]
    bx[..., 1, 0], bx[..., 1, 2] = b[..., 2], -b[..., 0]
    bx[..., 2, 0], bx[..., 2, 1] = -b[..., 1], b[..., 0]
    A = (bx * scale[..., None, None]).reshape(len(b), 6, 3)
    rhs = (-np.cross(b, q) * scale[..., None]).reshape(len(b), 6)
    U, S, Vt = np.linalg.svd(A, full_matrices=False)
    cutoff = 1e-9 * S.max(axis=1, keepdims=True)
    inverse = np.where(S > cutoff, 1.0 / np.where(S > 0, S, 1.0), 0.0)
    coefficients = inverse * np.einsum("sij,si->sj", U, rhs)
    t = np.einsum("sji,sj->si", Vt, coefficients)
    t[~np.all(np.isfinite(t), axis=1)] = 0.0
    return t


def translation_ransac(
    camera: CameraModel,
    R_camera_lidar,
    uv_camera,
    points_lidar,
    bearings_camera,
    *,
    threshold: float = 5.0,
    iterations: int = 1000,
    seed: int = 0,
    t_start=None,
    max_norm: float = 5.0,
) -> tuple[np.ndarray, int]:
    """The translation, for a fixed rotation, that reprojects the most correspondences.

    Two correspondences fix ``t`` once ``R`` is known (:func:`translation_from_bearings` of the
    pair); each random pair is a hypothesis, scored by its inliers (reprojection error below
    ``threshold`` pixels) over all correspondences. ``t_start`` (if given) is scored first and
    kept unless a hypothesis explains strictly more; among hypotheses that explain the most,
    the first drawn wins. The hypotheses are solved and scored in batches;
    :func:`nbcalib.reference.ransac.translation_ransac` is the same, one hypothesis at a time.

    Parameters
    ----------
    camera : CameraModel
    R_camera_lidar : array_like of shape (3, 3)
    uv_camera : array_like of shape (M, 2)
        Camera keypoints, pixels.
    points_lidar : array_like of shape (M, 3)
        Their 3-D points in the LiDAR frame, metres.
    bearings_camera : array_like of shape (M, 3)
        Unit camera rays of the keypoints.
    threshold : float, optional
        Inlier threshold, pixels.
    iterations : int, optional
        Hypotheses drawn.
    seed : int, optional
        Seed of the draws: the same seed gives the same result.
    t_start : array_like of shape (3,), optional
        Current translation, the one to beat.
    max_norm : float, optional
        Hypotheses longer than this (metres) are skipped.

    Returns
    -------
    t : ndarray of shape (3,), float64
        Translation of ``T_camera_lidar``, metres.
    inliers : int
        Its inlier count.
    """
    R = np.asarray(R_camera_lidar, dtype=np.float64)
    uv = np.asarray(uv_camera, dtype=np.float64)
    points = np.asarray(points_lidar, dtype=np.float64)
    bearings = np.asarray(bearings_camera, dtype=np.float64)
    best_t = np.zeros(3) if t_start is None else np.asarray(t_start, dtype=np.float64)
    best_n = int(_inlier_counts(camera, R, best_t, uv, points, threshold)[0])
    iterations = operator.index(iterations)
    if len(uv) < 2 or iterations <= 0:
        return best_t, best_n
    rng = np.random.default_rng(seed)
    samples = np.array([rng.choice(len(uv), size=2, replace=False) for _ in range(iterations)])
    ts = _translations_of_pairs(R, bearings[samples], points[samples])
    ts = ts[np.linalg.norm(ts, axis=1) <= max_norm]
    for k in range(0, len(ts), _HYPOTHESES_PER_BATCH):
        batch = ts[k : k + _HYPOTHESES_PER_BATCH]
        counts = _inlier_counts(camera, R, batch, uv, points, threshold)
        j = int(np.argmax(counts))  # the first of the most
        if counts[j] > best_n:
            best_t, best_n = batch[j].copy(), int(counts[j])
    return best_t, best_n


def _polish(camera, uv, points, bearings, T, weights, *, threshold, width, seed, iterations):
    """Translation RANSAC for the rotation of ``T``, then LM refits of the inliers."""
    t, _ = translation_ransac(
        camera,
        T[:3, :3],
        uv,
        points,
        bearings,
        threshold=threshold,
        iterations=iterations,
        seed=seed,
        t_start=T[:3, 3],
    )
    T = make_T(T[:3, :3], t)
    previous = None
    for _ in range(_POLISH_ROUNDS):
        current = reprojection_errors(camera, T, uv, points)[0] < threshold
        if np.count_nonzero(current) < MIN_CORRESPONDENCES or np.array_equal(current, previous):
            break
        previous = current
        T = refine_pose_lm(
            camera,
            uv[current],
            points[current],
            T,
            robust_kernel_width=width,
            weights=weights[current],
        ).T_camera_lidar
    return T


def estimate_initial_guess(
    camera: CameraModel,
    uv_camera,
    points_lidar,
    config: InitialGuessConfig | None = None,
    *,
    seed: int = 0,
    weights=None,
    **overrides,
) -> InitialGuess:
    """Estimate ``T_camera_lidar`` from 2D-3D correspondences (paper section III-D).

    Steps: rotation-only RANSAC over all correspondences; for each of the ``candidates`` best
    RANSAC rotations (distinct by at least 1 degree), a start translation and robust LM; the
    candidate with the most final inliers wins (then the lower cost). Candidates are refined in
    rank order and the rest skipped once the best pose has at least ``min_inliers`` inliers and
    three times the RANSAC inliers of the next candidate. With
    ``local_optimization``, LM first fits the hypothesis's own RANSAC inliers, then all
    correspondences, and repeats (up to 3 times) "fit the current inliers, then all" while the
    inlier set changes; the last stage always minimises paper Eq. 1 over all correspondences.
    With ``polish`` the winner is then polished (translation RANSAC, LM refits of its inliers).
    ``candidates=1, local_optimization=False, initial_translation="zero", polish=False`` is the
    reference toolbox's procedure.

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    uv_camera : array_like of shape (M, 2)
        Camera keypoints, pixels (u = column, v = row).
    points_lidar : array_like of shape (M, 3)
        Their 3-D points in the LiDAR frame, metres. Outliers are expected.
    config : InitialGuessConfig, optional
        RANSAC, LM, polish and success-test settings (its attributes are documented there);
        default ``InitialGuessConfig()``.
    seed : int, optional
        RANSAC seed; the same seed gives the same result.
    weights : array_like of shape (M,), optional
        Non-negative weight of each correspondence in the LM cost, ``sum c_j rho(s_j)``, e.g.
        the matcher's confidences (the correct fraction of learned matches rises steeply with
        their confidence; docs/BENCHMARKS.md). Default: all 1, paper Eq. 1. RANSAC and the
        inlier counts do not use them.
    **overrides
        Attributes of :class:`InitialGuessConfig` to change for this call
        (``ransac_iterations=2000``, ``polish=False``, ...).

    Returns
    -------
    InitialGuess

    Raises
    ------
    InputError
        Fewer than :data:`MIN_CORRESPONDENCES` usable correspondences.
    """
    cfg = replace(config or InitialGuessConfig(), **overrides)
    key = _memo_key(camera, uv_camera, points_lidar, cfg, seed, weights)
    if key is not None and key in _MEMO:
        return _MEMO[key]
    guess = _estimate(camera, uv_camera, points_lidar, cfg, seed, weights)
    if key is not None:
        _MEMO[key] = guess
        while len(_MEMO) > _MEMO_SIZE:
            del _MEMO[next(iter(_MEMO))]
    return guess


#: Estimates kept for the same inputs asked again: matching tests whether a pair's
#: correspondences give a guess, and the initial-guess stage of the same job then estimates
#: from the same correspondences (``nbcalib run``, :func:`nbcalib.calibrate`: 1.4 s a pair).
_MEMO: dict = {}
_MEMO_SIZE = 4


def _memo_key(camera, uv_camera, points_lidar, cfg, seed, weights) -> tuple | None:
    """A digest of every input of an estimate (None when an input is not an array of numbers)."""
    import hashlib

    try:
        arrays = [np.ascontiguousarray(uv_camera, dtype=np.float64)]
        arrays.append(np.ascontiguousarray(points_lidar, dtype=np.float64))
        if weights is not None:
            arrays.append(np.ascontiguousarray(weights, dtype=np.float64))
    except (TypeError, ValueError):
        return None
    digest = hashlib.blake2b(digest_size=16)
    for a in arrays:
        digest.update(repr(a.shape).encode())
        digest.update(a.tobytes())
    return (camera, cfg, int(seed), weights is None, digest.hexdigest())


def _estimate(camera, uv_camera, points_lidar, cfg, seed, weights) -> InitialGuess:
    """:func:`estimate_initial_guess` with its settings resolved (no memo)."""
    min_inliers = operator.index(cfg.min_inliers)
    ransac_threshold = cfg.ransac_threshold
    bearings_camera, _, usable = usable_correspondences(camera, uv_camera, points_lidar)
    n_usable = int(np.count_nonzero(usable))
    if n_usable < MIN_CORRESPONDENCES:
        raise InputError(
            f"too few correspondences: {n_usable} usable (of {len(usable)}), "
            f"need at least {MIN_CORRESPONDENCES}"
        )
    uv = np.ascontiguousarray(uv_camera, dtype=np.float64)
    points = np.ascontiguousarray(points_lidar, dtype=np.float64)
    if weights is None:
        weights = np.ones(len(uv))
    weights = np.asarray(weights, dtype=np.float64)
    if weights.shape != (len(uv),) or not np.all(np.isfinite(weights)) or np.any(weights < 0):
        raise ValueError(f"weights must be ({len(uv)},) finite and >= 0, got shape {weights.shape}")
    ransac = estimate_rotation_ransac(
        camera,
        uv,
        points,
        iterations=cfg.ransac_iterations,
        threshold=ransac_threshold,
        seed=seed,
        parallel=cfg.parallel,
    )
    hypotheses = ransac.ranked_hypotheses(cfg.candidates, min_inliers=0)
    # LM on the usable correspondences only: the others have no valid camera ray
    uv_u, points_u, bearings_u = uv[usable], points[usable], bearings_camera[usable]
    best = None
    for rank, (_, _, R) in enumerate(hypotheses):
        support = ransac.inlier_mask(R)[usable]
        T_start, result = _refine_from(
            camera,
            uv_u,
            points_u,
            bearings_u,
            R,
            support,
            initial_translation=cfg.initial_translation,
            max_initial_translation=cfg.max_initial_translation,
            threshold=ransac_threshold,
            robust_kernel_width=cfg.robust_kernel_width,
            local_optimization=cfg.local_optimization,
            max_lm_iterations=cfg.max_lm_iterations,
            weights=weights[usable],
        )
        key = (int(np.count_nonzero(result.errors < ransac_threshold)), -result.cost)
        if best is None or key > best[0]:
            best = (key, rank, T_start, result)
        # stop when the best pose explains far more than the next hypothesis could start from
        next_count = hypotheses[rank + 1][1] if rank + 1 < len(hypotheses) else 0
        if best[0][0] >= max(min_inliers, _EARLY_STOP_RATIO * next_count):
            break
    _, rank, T_start, refinement = best
    errors = np.full(len(uv), np.inf)
    errors[usable] = refinement.errors
    T_final = refinement.T_camera_lidar
    if cfg.polish:
        T_final = _polish(
            camera,
            uv_u,
            points_u,
            bearings_u,
            T_final,
            weights[usable],
            threshold=ransac_threshold,
            width=cfg.polish_kernel_width,
            seed=seed,
            iterations=cfg.translation_iterations,
        )
        errors[usable] = reprojection_errors(camera, T_final, uv_u, points_u)[0]
    inliers = errors < ransac_threshold
    n_inliers = int(np.count_nonzero(inliers))
    rms = float(np.sqrt(np.mean(errors[inliers] ** 2))) if n_inliers else math.nan
    R_final = T_final[:3, :3]
    support = n_inliers
    runner_up = runner_up_shared = 0
    if cfg.min_distinctiveness > 0 or cfg.min_shared_distinctiveness > 0:
        runner_up, runner_up_shared = _runner_up(
            camera,
            ransac,
            R_final,
            uv_u,
            points_u,
            bearings_u,
            ~inliers[usable],
            threshold=ransac_threshold,
            seed=seed,
            iterations=cfg.translation_iterations,
        )
    bound_m, bound_deg = pose_uncertainty(camera, T_final, uv[inliers], points[inliers])
    guess = InitialGuess(
        T_camera_lidar=T_final,
        inliers=inliers,
        errors=errors,
        rms_px=rms,
        success=False,  # set below from found and precise
        threshold=float(ransac_threshold),
        min_inliers=min_inliers,
        ransac=ransac,
        refinement=refinement,
        T_camera_lidar_start=T_start,
        candidate=rank,
        support=support,
        runner_up=runner_up,
        min_distinctiveness=float(cfg.min_distinctiveness),
        runner_up_shared=runner_up_shared,
        min_shared_distinctiveness=float(cfg.min_shared_distinctiveness),
        bound_m=bound_m,
        bound_deg=bound_deg,
        precision_scale=float(cfg.precision_scale),
        max_error_m=float(cfg.max_start_translation),
        max_error_deg=float(cfg.max_start_rotation_deg),
    )
    return replace(guess, success=guess.found and guess.precise)


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
            camera, R, uv, points, bearings, threshold=threshold, iterations=iterations, seed=seed
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
            )
        else:
            n = n_free
        own = max(own, n)
    return own, shared
