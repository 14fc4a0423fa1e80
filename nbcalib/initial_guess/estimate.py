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

The result says how far it can be trusted (:mod:`~nbcalib.initial_guess.success`: enough
inliers, distinct from rival poses, precise); translations for a known rotation are in
:mod:`~nbcalib.initial_guess.translation`.
"""

from __future__ import annotations

import math
import operator
from dataclasses import replace

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.initial_guess.config import INITIAL_TRANSLATIONS, InitialGuessConfig
from nbcalib.initial_guess.lm import refine_pose_lm, reprojection_errors
from nbcalib.initial_guess.ransac import estimate_rotation_ransac, usable_correspondences
from nbcalib.initial_guess.success import (
    DISTINCT_ROTATION_DEG,
    InitialGuess,
    _runner_up,
    pose_uncertainty,
)
from nbcalib.initial_guess.translation import translation_from_bearings, translation_ransac
from nbcalib.transforms import make_T

__all__ = [
    "DISTINCT_ROTATION_DEG",
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

#: Fewest correspondences the estimate accepts (a pose has 6 degrees of freedom, each
#: correspondence gives 2 equations; the reference's manual tool asks for 3 as well).
MIN_CORRESPONDENCES = 3


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
    origin=None,
):
    """LM from one rotation hypothesis; returns (start pose, LM result of the last stage).

    The start's translation is found (``"bearing"``) or taken (``"zero"``) for the camera at
    ``origin``, the LiDAR's position in the points' frame (default: their origin).
    """
    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    relative = points if origin is None else points - o
    t = np.zeros(3)
    if initial_translation == "bearing":
        t = translation_from_bearings(
            R, bearings_camera[support], relative[support], max_norm=max_initial_translation
        )
    if origin is not None:
        t = t - R @ o  # R (p - o) + t = R p + (t - R o)
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


def _polish(
    camera, uv, points, bearings, T, weights, *, threshold, width, seed, iterations, origin=None
):
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
        origin=origin,
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
    origin=None,
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
    origin : array_like of shape (3,), optional
        Where the LiDAR sits in the points' frame (:mod:`nbcalib.preprocess.origin`; default:
        at their origin). Rotation-only RANSAC takes the camera to be there (its bearings are
        the points' directions from it), and so do the start translations; the result is in
        the points' frame.
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
    if origin is not None:
        origin = np.asarray(origin, dtype=np.float64)
        if origin.shape != (3,) or not np.all(np.isfinite(origin)):
            raise ValueError(f"origin must be 3 finite numbers, got {origin!r}")
        origin = origin if origin.any() else None  # the points' own origin: as without one
    key = _memo_key(camera, uv_camera, points_lidar, cfg, seed, weights, origin)
    if key is not None and key in _MEMO:
        return _MEMO[key]
    guess = _estimate(camera, uv_camera, points_lidar, cfg, seed, weights, origin)
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


def _memo_key(camera, uv_camera, points_lidar, cfg, seed, weights, origin=None) -> tuple | None:
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
    where = None if origin is None else tuple(float(v) for v in origin)
    return (camera, cfg, int(seed), weights is None, where, digest.hexdigest())


def _estimate(camera, uv_camera, points_lidar, cfg, seed, weights, origin=None) -> InitialGuess:
    """:func:`estimate_initial_guess` with its settings resolved (no memo)."""
    min_inliers = operator.index(cfg.min_inliers)
    ransac_threshold = cfg.ransac_threshold
    # rotation-only RANSAC sees the points from the LiDAR (the camera is taken to be there)
    seen = points_lidar if origin is None else np.asarray(points_lidar, dtype=np.float64) - origin
    bearings_camera, _, usable = usable_correspondences(camera, uv_camera, seen)
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
        points if origin is None else points - origin,
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
            origin=origin,
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
            origin=origin,
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
            origin=origin,
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
