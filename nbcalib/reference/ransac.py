"""Slow, readable reference of the rotation-only RANSAC kernels in :mod:`nbcalib.kernels.ransac`.

Paper Algorithm 1, one iteration at a time in plain Python, with the kernel's random streams
(SplitMix64 on Python integers), sample rule, Kabsch rotation (``numpy.linalg.svd``), inlier test
and tie rule (the lowest iteration wins). The projection is the camera kernel
:func:`nbcalib.kernels.projection.project_point` called from Python; it has its own reference in
:mod:`nbcalib.reference.camera`.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels.projection import project_point

__all__ = [
    "draw",
    "hypothesis_counts",
    "inlier_mask",
    "rotation_from_pair",
    "rotation_ransac",
    "sample_pair",
    "translation_ransac",
]

_MASK64 = (1 << 64) - 1
_GOLDEN = 0x9E3779B97F4A7C15


def draw(seed: int, k: int) -> int:
    """Draw ``k`` of the SplitMix64 sequence of ``seed``: an integer in [0, 2**64)."""
    z = (seed + (k + 1) * _GOLDEN) & _MASK64
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def _uniform_index(z: int, m: int) -> int:
    x = (z >> 11) * 2.0**-53  # top 53 bits as a float in [0, 1)
    return min(math.floor(x * m), m - 1)


def sample_pair(seed: int, iteration: int, m: int) -> tuple[int, int]:
    """The two distinct correspondence indices that iteration ``iteration`` uses."""
    j0 = _uniform_index(draw(seed, 2 * iteration), m)
    j1 = (j0 + 1 + _uniform_index(draw(seed, 2 * iteration + 1), m - 1)) % m
    return j0, j1


def rotation_from_pair(c0, c1, l0, l1) -> np.ndarray:
    """Kabsch: the rotation ``R`` that best maps LiDAR bearings ``l0, l1`` onto ``c0, c1``.

    ``H = c0 l0^T + c1 l1^T = U S V^T``; ``R = U diag(1, 1, s) V^T`` with ``s = sign(det U det V)``.
    """
    H = np.outer(c0, l0) + np.outer(c1, l1)
    U, _, Vt = np.linalg.svd(H)
    s = 1.0 if np.linalg.det(U) * np.linalg.det(Vt) >= 0.0 else -1.0
    return U @ np.diag([1.0, 1.0, s]) @ Vt


def inlier_mask(model_id, params, R, bearings_lidar, uv, threshold) -> np.ndarray:
    """Which correspondences ``R l_j`` projects to within ``threshold`` pixels of ``uv_j``."""
    mask = np.zeros(len(bearings_lidar), dtype=bool)
    for j, (l, (u_obs, v_obs)) in enumerate(zip(bearings_lidar, uv)):
        X = R[0, 0] * l[0] + R[0, 1] * l[1] + R[0, 2] * l[2]
        Y = R[1, 0] * l[0] + R[1, 1] * l[1] + R[1, 2] * l[2]
        Z = R[2, 0] * l[0] + R[2, 1] * l[1] + R[2, 2] * l[2]
        u, v, ok = project_point(model_id, params, X, Y, Z)
        du, dv = u - u_obs, v - v_obs
        mask[j] = bool(ok) and du * du + dv * dv < threshold * threshold
    return mask


def hypothesis_counts(
    model_id, params, bearings_camera, bearings_lidar, uv, threshold, iterations, seed
) -> np.ndarray:
    """Inlier count of every RANSAC hypothesis, one after another.

    Parameters
    ----------
    model_id : int
        ``camera.model_id``.
    params : ndarray of shape (16,), float64
        ``camera.params``.
    bearings_camera, bearings_lidar : ndarray of shape (M, 3), float64
        Unit bearings in the camera and LiDAR frames, ``M >= 2``.
    uv : ndarray of shape (M, 2), float64
        The camera keypoints, pixels.
    threshold : float
        Inlier threshold, pixels.
    iterations : int
        Number of hypotheses.
    seed : int
        Seed in [0, 2**64).

    Returns
    -------
    ndarray of shape (iterations,), int64
    """
    m = len(bearings_camera)
    counts = np.zeros(iterations, dtype=np.int64)
    for i in range(iterations):
        j0, j1 = sample_pair(seed, i, m)
        c0, c1 = bearings_camera[j0], bearings_camera[j1]
        R = rotation_from_pair(c0, c1, bearings_lidar[j0], bearings_lidar[j1])
        counts[i] = inlier_mask(model_id, params, R, bearings_lidar, uv, threshold).sum()
    return counts


def rotation_ransac(
    model_id, params, bearings_camera, bearings_lidar, uv, threshold, iterations, seed
) -> tuple[int, int, np.ndarray]:
    """Rotation-only RANSAC (Algorithm 1): the first hypothesis with the most inliers.

    Parameters as :func:`hypothesis_counts`.

    Returns
    -------
    best_iteration : int
        First iteration with the most inliers.
    best_count : int
    R_camera_lidar : ndarray of shape (3, 3)
        Its rotation.
    """
    m = len(bearings_camera)
    best_iteration, best_count, best_R = -1, -1, None
    for i in range(iterations):
        j0, j1 = sample_pair(seed, i, m)
        c0, c1 = bearings_camera[j0], bearings_camera[j1]
        R = rotation_from_pair(c0, c1, bearings_lidar[j0], bearings_lidar[j1])
        count = int(inlier_mask(model_id, params, R, bearings_lidar, uv, threshold).sum())
        if count > best_count:  # strict: the lowest iteration wins a tie
            best_iteration, best_count, best_R = i, count, R
    return best_iteration, best_count, best_R


def translation_ransac(
    camera, R, uv, points, bearings, *, threshold=5.0, iterations=1000, seed=0, t_start=None,
    max_norm=5.0,
):  # fmt: skip
    """:func:`nbcalib.initial_guess.estimate.translation_ransac`, one hypothesis at a time."""
    from nbcalib.initial_guess.estimate import translation_from_bearings

    def inliers(t):
        proj, valid = camera.project(points @ R.T + t)
        return int(np.count_nonzero(valid & (np.linalg.norm(proj - uv, axis=1) < threshold)))

    best_t = np.zeros(3) if t_start is None else np.asarray(t_start, dtype=np.float64)
    best_n = inliers(best_t)
    if len(uv) < 2:
        return best_t, best_n
    rng = np.random.default_rng(seed)
    for _ in range(iterations):
        j = rng.choice(len(uv), size=2, replace=False)
        t = translation_from_bearings(R, bearings[j], points[j])
        if not np.linalg.norm(t) <= max_norm:
            continue
        n = inliers(t)
        if n > best_n:
            best_t, best_n = t, n
    return best_t, best_n
