"""The translation of ``T_camera_lidar`` for a known rotation, from 2D-3D correspondences.

- :func:`translation_from_bearings`: the least-squares translation that puts each point on its
  keypoint's ray (linear in ``t``); the start of LM from a RANSAC rotation;
- :func:`translation_ransac`: the translation two correspondences fix, hypothesised from random
  pairs and scored by full-pose reprojection inliers: the polish of the winner and the rival
  poses of the success test (:mod:`nbcalib.initial_guess.success`).
"""

from __future__ import annotations

import operator

import numpy as np

from nbcalib.camera import CameraModel

__all__ = ["translation_from_bearings", "translation_ransac"]


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
    origin=None,
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
        Hypotheses that put the camera farther than this from ``origin`` (metres) are skipped.
    origin : array_like of shape (3,), optional
        Where the LiDAR sits in the points' frame (default: their origin).

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
    centre = np.zeros(3) if origin is None else -R @ np.asarray(origin, dtype=np.float64)
    ts = ts[np.linalg.norm(ts - centre, axis=1) <= max_norm]
    for k in range(0, len(ts), _HYPOTHESES_PER_BATCH):
        batch = ts[k : k + _HYPOTHESES_PER_BATCH]
        counts = _inlier_counts(camera, R, batch, uv, points, threshold)
        j = int(np.argmax(counts))  # the first of the most
        if counts[j] > best_n:
            best_t, best_n = batch[j].copy(), int(counts[j])
    return best_t, best_n
