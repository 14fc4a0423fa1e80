"""Reference of :mod:`nbcalib.kernels.normals`: a neighbourhood's scatter matrix, one at a time."""

from __future__ import annotations

import numpy as np

__all__ = ["neighbourhood_covariances"]


def neighbourhood_covariances(points, neighbours) -> np.ndarray:
    """``sum_j (p_j - mean)(p_j - mean)^T`` over the rows ``neighbours[i]`` of ``points``."""
    points = np.asarray(points, dtype=np.float64)
    out = np.empty((len(neighbours), 3, 3))
    for i, rows in enumerate(np.asarray(neighbours)):
        centred = points[rows] - points[rows].mean(axis=0)
        out[i] = centred.T @ centred
    return out
