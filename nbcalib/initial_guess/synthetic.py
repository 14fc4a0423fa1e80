"""Synthetic 2D-3D correspondences with known answer, for tests, benchmarks and notebooks.

True correspondences are camera pixels with points on their rays at random ranges, seen from the
LiDAR; their pixels get Gaussian noise. Outliers imitate a matcher run at a very low threshold:
a random camera keypoint paired with either a point the camera also sees (elsewhere in the
image: structured outliers) or any point around the LiDAR (possibly behind the camera).
"""

from __future__ import annotations

import operator
from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.transforms import invert_T, transform_points, validate_T

__all__ = ["SyntheticCorrespondences", "synthetic_correspondences"]


@dataclass(frozen=True)
class SyntheticCorrespondences:
    """Correspondences with ground truth.

    Attributes
    ----------
    uv_camera : ndarray of shape (M, 2), float64
        Camera keypoints, pixels.
    points_lidar : ndarray of shape (M, 3), float64
        Their 3-D points, LiDAR frame, metres.
    is_inlier : ndarray of shape (M,), bool
        True correspondences (before noise).
    T_camera_lidar : ndarray of shape (4, 4), float64
        The truth.
    """

    uv_camera: np.ndarray
    points_lidar: np.ndarray
    is_inlier: np.ndarray
    T_camera_lidar: np.ndarray


def _random_pixels_with_rays(camera: CameraModel, rng, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` uniform in-image pixels whose bearings are valid, and those bearings."""
    uv = np.empty((0, 2))
    bearings = np.empty((0, 3))
    while len(uv) < n:
        cand = rng.uniform([-0.5, -0.5], [camera.width - 0.5, camera.height - 0.5], (2 * n, 2))
        b = camera.unproject(cand)
        ok = np.all(np.isfinite(b), axis=1)
        uv = np.concatenate([uv, cand[ok]])
        bearings = np.concatenate([bearings, b[ok]])
    return uv[:n], bearings[:n]


def _log_uniform(rng, lo: float, hi: float, n: int) -> np.ndarray:
    return np.exp(rng.uniform(np.log(lo), np.log(hi), n))


def synthetic_correspondences(
    camera: CameraModel,
    T_camera_lidar,
    rng: np.random.Generator | int,
    *,
    n_inliers: int = 100,
    outlier_fraction: float = 0.8,
    noise_px: float = 1.0,
    range_m: tuple[float, float] = (2.0, 40.0),
) -> SyntheticCorrespondences:
    """Draw ``n_inliers`` true correspondences plus outliers, shuffled.

    Parameters
    ----------
    camera : CameraModel
        The camera.
    T_camera_lidar : array_like of shape (4, 4)
        The true ``p_camera = T_camera_lidar @ p_lidar``.
    rng : numpy.random.Generator or int
        Generator or seed.
    n_inliers : int, optional
        True correspondences: uniform in-image keypoints, ranges log-uniform in ``range_m``
        from the camera, pixel noise ``N(0, noise_px^2)`` per axis.
    outlier_fraction : float, optional
        Fraction of outliers among all correspondences, in [0, 1). Half of them pair a keypoint
        with a point the camera sees elsewhere, half with a point in a uniform direction around
        the LiDAR.
    noise_px : float, optional
        Keypoint noise, pixels.
    range_m : tuple of float, optional
        Range interval of the points, metres.

    Returns
    -------
    SyntheticCorrespondences
    """
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    T = validate_T(T_camera_lidar, name="T_camera_lidar")
    n_inliers = operator.index(n_inliers)
    if n_inliers < 0:
        raise ValueError(f"n_inliers must be >= 0, got {n_inliers}")
    if not 0.0 <= outlier_fraction < 1.0:
        raise ValueError(f"outlier_fraction must be in [0, 1), got {outlier_fraction}")
    lo, hi = (float(r) for r in range_m)
    if not 0.0 < lo <= hi:
        raise ValueError(f"range_m must be 0 < min <= max, got {range_m}")
    gen = np.random.default_rng(rng)
    T_lidar_camera = invert_T(T)

    uv_true, bearings = _random_pixels_with_rays(camera, gen, n_inliers)
    points_in = transform_points(
        T_lidar_camera, bearings * _log_uniform(gen, lo, hi, n_inliers)[:, None]
    )
    uv_in = uv_true + gen.normal(0.0, noise_px, uv_true.shape)

    n_out = round(n_inliers * outlier_fraction / (1.0 - outlier_fraction))
    n_seen = n_out // 2
    uv_out, _ = _random_pixels_with_rays(camera, gen, n_out)
    _, other_rays = _random_pixels_with_rays(camera, gen, n_seen)
    seen = transform_points(T_lidar_camera, other_rays * _log_uniform(gen, lo, hi, n_seen)[:, None])
    directions = gen.normal(size=(n_out - n_seen, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    anywhere = directions * _log_uniform(gen, lo, hi, n_out - n_seen)[:, None]
    points_out = np.concatenate([seen.reshape(-1, 3), anywhere])

    uv = np.concatenate([uv_in, uv_out])
    points = np.concatenate([points_in.reshape(-1, 3), points_out])
    is_inlier = np.arange(len(uv)) < n_inliers
    order = gen.permutation(len(uv))
    return SyntheticCorrespondences(uv[order], points[order], is_inlier[order], T.copy())
