"""The classical fallback: OpenCV SIFT keypoints, Lowe's ratio test, mutual nearest neighbours.

Runs without any exported model (OpenCV is a core dependency). Across the LiDAR-intensity vs
camera gap it finds far fewer correct matches than the learned matchers (docs/BENCHMARKS.md,
"Matching"); it is there so that ``find-matches`` always produces something.
"""

from __future__ import annotations

import numpy as np

__all__ = ["sift_features", "sift_match"]


def sift_features(image: np.ndarray, *, max_keypoints: int = 4096):
    """SIFT keypoints and descriptors of a grey image.

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8
        Grey image.
    max_keypoints : int, optional
        Keep at most this many keypoints (the strongest; 0 keeps all).

    Returns
    -------
    keypoints : ndarray of shape (N, 2), float64
        ``(u, v)`` pixels, centres at integers (OpenCV's convention).
    descriptors : ndarray of shape (N, 128), float32
    """
    import cv2

    sift = cv2.SIFT_create(nfeatures=int(max_keypoints))
    kps, desc = sift.detectAndCompute(np.ascontiguousarray(image), None)
    if desc is None or len(kps) == 0:
        return np.zeros((0, 2)), np.zeros((0, 128), dtype=np.float32)
    keypoints = np.array([kp.pt for kp in kps], dtype=np.float64)
    return keypoints, np.asarray(desc, dtype=np.float32)


def sift_match(
    desc0: np.ndarray, desc1: np.ndarray, *, ratio: float = 0.8, mutual: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Match SIFT descriptors: nearest neighbour, Lowe's ratio test, optionally mutual.

    Parameters
    ----------
    desc0 : ndarray of shape (M, 128), float32
    desc1 : ndarray of shape (N, 128), float32
    ratio : float, optional
        A match needs ``d_best < ratio * d_second`` (Lowe's 0.8).
    mutual : bool, optional
        Also require the camera keypoint to be the LiDAR keypoint's nearest neighbour.

    Returns
    -------
    matches0 : ndarray of shape (M,), int64
        Index into ``desc1`` or -1.
    confidence : ndarray of shape (M,), float64
        ``1 - d_best / d_second`` for every keypoint with two neighbours (also rejected ones),
        in [0, 1].
    """
    import cv2

    if not 0.0 < ratio <= 1.0:
        raise ValueError(f"ratio must be in (0, 1], got {ratio}")
    m, n = len(desc0), len(desc1)
    matches0 = np.full(m, -1, dtype=np.int64)
    confidence = np.zeros(m)
    if m == 0 or n < 2:
        return matches0, confidence
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    knn = matcher.knnMatch(desc0, desc1, k=2)
    best = np.full(m, -1, dtype=np.int64)
    for pair in knn:
        if len(pair) < 2:
            continue
        first, second = pair
        i = first.queryIdx
        best[i] = first.trainIdx
        confidence[i] = 1.0 - first.distance / max(second.distance, 1e-12)
    accept = (best >= 0) & (confidence > 1.0 - ratio)
    if mutual:
        back = matcher.match(desc1, desc0)
        nearest1 = np.full(n, -1, dtype=np.int64)
        for match in back:
            nearest1[match.queryIdx] = match.trainIdx
        accept &= nearest1[np.clip(best, 0, None)] == np.arange(m)
    matches0[accept] = best[accept]
    return matches0, np.clip(confidence, 0.0, 1.0)
