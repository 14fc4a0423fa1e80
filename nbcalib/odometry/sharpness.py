"""Sharpness of a dense cloud: how blurred its surfaces are (a check of the deskewing)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from nbcalib.odometry.scans import _points_arg

__all__ = ["local_thickness"]


def local_thickness(
    points: Any,
    *,
    k: int = 20,
    max_distance: float = 0.3,
    n_samples: int = 20000,
    min_planarity: float = 0.5,
    direction: Any = None,
    min_alignment: float = 0.7,
    seed: int = 0,
) -> float:
    """Median local thickness of a cloud: how blurred its surfaces are.

    For ``n_samples`` points drawn at random (with ``seed``), the ``k`` nearest points within
    ``max_distance`` are fitted with a plane by PCA; the thickness is the standard deviation
    along the normal, ``sqrt(l0)`` of the smallest eigenvalue. Only planar neighbourhoods count
    (CT-ICP planarity ``(sqrt(l1) - sqrt(l0)) / sqrt(l2) >= min_planarity``, so edges and
    vegetation do not dominate). Motion blur of an accumulated cloud thickens its surfaces, so a
    better-deskewed cloud has a smaller value. A motion blurs only the surfaces it moves along
    their normal (driving forward smears walls facing the car, not the road nor the facades
    along it): ``direction`` keeps the surfaces whose normal is within ``acos(min_alignment)``
    of it.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        The cloud, metres.
    k : int
        Neighbours per sample.
    max_distance : float
        Neighbour radius, metres.
    n_samples : int
        Number of sample points.
    min_planarity : float
        Planarity a sample neighbourhood needs to count.
    direction : array_like of shape (3,), optional
        Keep only surfaces whose unit normal ``n`` has ``|n . direction| >= min_alignment``
        (``direction`` is normalised).
    min_alignment : float
        See ``direction``.
    seed : int
        Seed of the sampling.

    Returns
    -------
    float
        Median thickness, metres (NaN if no neighbourhood qualifies).
    """
    from scipy.spatial import cKDTree

    points = _points_arg(points, "points")
    rng = np.random.default_rng(seed)
    n = points.shape[0]
    if n == 0:
        return math.nan
    samples = rng.choice(n, size=min(n_samples, n), replace=False)
    tree = cKDTree(points)
    d, idx = tree.query(points[samples], k=k, distance_upper_bound=max_distance)
    full = np.isfinite(d).all(axis=1)
    if not full.any():
        return math.nan
    nb = points[idx[full]]  # (M, k, 3)
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", centred, centred) / k
    eig, vec = np.linalg.eigh(cov)  # ascending
    eig = np.clip(eig, 0.0, None)
    planarity = (np.sqrt(eig[:, 1]) - np.sqrt(eig[:, 0])) / np.sqrt(np.maximum(eig[:, 2], 1e-30))
    good = planarity >= min_planarity
    if direction is not None:
        u = np.asarray(direction, dtype=np.float64)
        u = u / np.linalg.norm(u)
        good &= np.abs(vec[:, :, 0] @ u) >= min_alignment
    if not good.any():
        return math.nan
    return float(np.median(np.sqrt(eig[good, 0])))
