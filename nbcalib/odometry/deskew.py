"""Deskewing: each point of a scan moved with the pose interpolated at its own time.

The pose at normalised time ``s`` slerps the rotations and lerps the translations of the poses
at the first and at the last point of the scan (``docs/conventions.md``); the kernels are in
:mod:`nbcalib.kernels.ct_icp`, the reference is :func:`nbcalib.reference.integrate.deskew`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nbcalib.odometry.scans import _points_arg

__all__ = ["deskew"]


def _pose_parts(T: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    from nbcalib.transforms import validate_T

    T = validate_T(T, name=name)
    return np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])


def _relative_rotation_vector(R_b: np.ndarray, R_e: np.ndarray) -> np.ndarray:
    from nbcalib.kernels.lie import so3_log

    return so3_log(np.ascontiguousarray(R_b.T @ R_e))


def deskew(
    points: Any, s: Any, T_world_begin: Any, T_world_end: Any, *, parallel: bool = False
) -> np.ndarray:
    """Move each point of a scan with the pose interpolated at its own time.

    ``p_world = T(s) p`` with ``T(s)`` = slerp of the rotations and lerp of the translations of
    ``T_world_begin`` and ``T_world_end`` (``docs/conventions.md``). Wraps
    :func:`nbcalib.kernels.ct_icp._deskew`; the reference is
    :func:`nbcalib.reference.integrate.deskew`.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        The scan in the LiDAR frame at each point's time, metres.
    s : array_like of shape (N,)
        Normalised point times in [0, 1] (:func:`normalized_scan_times`).
    T_world_begin, T_world_end : array_like of shape (4, 4)
        LiDAR poses at ``s = 0`` and ``s = 1`` in the target frame ``world``.
    parallel : bool
        Use the parallel kernel (same result).

    Returns
    -------
    ndarray of shape (N, 3), float64
        The points in frame ``world``, metres.
    """
    from nbcalib.kernels.ct_icp import _deskew, _deskew_parallel

    points = _points_arg(points, "points")
    s = np.ascontiguousarray(s, dtype=np.float64).reshape(-1)
    if s.shape[0] != points.shape[0]:
        raise ValueError(f"{s.shape[0]} times for {points.shape[0]} points")
    if not np.isfinite(s).all():
        raise ValueError("s must be finite")
    R_b, t_b = _pose_parts(T_world_begin, "T_world_begin")
    R_e, t_e = _pose_parts(T_world_end, "T_world_end")
    out = np.empty_like(points)
    kernel = _deskew_parallel if parallel else _deskew
    kernel(points, s, R_b, t_b, t_e, _relative_rotation_vector(R_b, R_e), out)
    return out
