"""How far a calibration is from the truth.

Errors are reported the way the paper and the reference toolbox's evaluation do: the rotation
error is the angle of ``R_est R_true^T``, and the translation error is the displacement of the
camera centre in the LiDAR frame, ``||t_est - t_true||`` of the ``T_lidar_camera`` poses.
"""

from __future__ import annotations

import numpy as np

from nbcalib.transforms import invert_T, pose_error

__all__ = ["interval_quantiles", "pose_errors"]


def pose_errors(T_camera_lidar_est: np.ndarray, T_camera_lidar_true: np.ndarray) -> dict:
    """Compute the translation and rotation error of an estimated extrinsic.

    Parameters
    ----------
    T_camera_lidar_est, T_camera_lidar_true : ndarray of shape (4, 4), float64
        Estimated and true ``p_camera = T_camera_lidar @ p_lidar``.

    Returns
    -------
    dict
        ``translation_error_m``: distance in metres between the estimated and true camera
        centres in the LiDAR frame (translations of the inverses, ``T_lidar_camera``);
        ``rotation_error_deg``: angle of ``R_est R_true^T`` in degrees, in [0, 180].
    """
    translation_error_m, rotation_error_deg = pose_error(
        invert_T(np.asarray(T_camera_lidar_est, dtype=np.float64)),
        invert_T(np.asarray(T_camera_lidar_true, dtype=np.float64)),
    )
    return {
        "translation_error_m": float(translation_error_m),
        "rotation_error_deg": float(rotation_error_deg),
    }


#: Seed of the Monte-Carlo quantiles of the total translation/rotation error (deterministic).
_QUANTILE_SEED = 20261123
_QUANTILE_SAMPLES = 20000


def interval_quantiles(
    covariance: np.ndarray, confidence: float
) -> tuple[np.ndarray, float, float]:
    """Half-widths and norm bounds of a Gaussian ``delta`` at ``confidence``.

    Parameters
    ----------
    covariance : ndarray of shape (6, 6), float64
        Covariance of ``delta = [v, omega]`` (m, rad).
    confidence : float
        In (0, 1).

    Returns
    -------
    half_widths : ndarray of shape (6,)
        ``z * sigma`` per axis (two-sided), metres then radians.
    translation_bound : float
        Quantile of ``|v|`` (metres), by seeded Monte Carlo.
    rotation_bound : float
        Quantile of ``|omega|`` (radians).
    """
    from statistics import NormalDist  # scipy.stats costs ~1 s to import

    cov = 0.5 * (covariance + covariance.T)
    sigma = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    z = NormalDist().inv_cdf(0.5 + confidence / 2.0)
    rng = np.random.default_rng(_QUANTILE_SEED)
    w, V = np.linalg.eigh(cov)
    samples = (rng.standard_normal((_QUANTILE_SAMPLES, 6)) * np.sqrt(np.clip(w, 0, None))) @ V.T
    t_bound = float(np.quantile(np.linalg.norm(samples[:, :3], axis=1), confidence))
    r_bound = float(np.quantile(np.linalg.norm(samples[:, 3:], axis=1), confidence))
    return z * sigma, t_bound, r_bound
