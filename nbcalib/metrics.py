"""How far a calibration is from the truth.

Errors are reported the way the paper and the reference toolbox's evaluation do: the rotation
error is the angle of ``R_est R_true^T``, and the translation error is the displacement of the
camera centre in the LiDAR frame, ``||t_est - t_true||`` of the ``T_lidar_camera`` poses.
"""

from __future__ import annotations

import numpy as np

from nbcalib.transforms import invert_T, pose_error


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
