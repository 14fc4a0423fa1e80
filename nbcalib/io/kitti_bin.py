"""KITTI Velodyne scans (``.bin``): float32 records ``x, y, z, reflectance``, no header."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io._files import read_bytes, write_bytes_atomic


def read_kitti_bin_fields(path) -> dict[str, np.ndarray]:
    """Read a KITTI Velodyne scan: float32 records ``x, y, z, reflectance``.

    Returns
    -------
    dict
        ``x``, ``y``, ``z`` (metres), ``intensity`` (the reflectance, 0..1), float32 (N,).
    """
    path = Path(path)
    data = read_bytes(path)
    if len(data) % 16:
        raise InputError(
            f"size {len(data)} bytes is not a multiple of 16 (float32 x, y, z, reflectance)",
            path=path,
        )
    records = np.frombuffer(data, dtype="<f4").reshape(-1, 4)
    return {
        name: records[:, k].astype(np.float32)
        for k, name in enumerate(("x", "y", "z", "intensity"))
    }


def write_kitti_bin(path, points: np.ndarray, intensity: np.ndarray) -> None:
    """Write a KITTI Velodyne ``.bin`` (float32 ``x, y, z, reflectance`` records), atomically.

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Metres, LiDAR frame.
    intensity : ndarray of shape (N,)
        Reflectance (KITTI's is in 0..1).
    """
    points = np.asarray(points)
    intensity = np.asarray(intensity)
    if points.ndim != 2 or points.shape[1] != 3 or intensity.shape != (points.shape[0],):
        raise ValueError(
            f"expected points (N, 3) and intensity (N,), got {points.shape}, {intensity.shape}"
        )
    records = np.empty((points.shape[0], 4), dtype="<f4")
    records[:, :3] = points
    records[:, 3] = intensity
    write_bytes_atomic(path, [records.tobytes()])
