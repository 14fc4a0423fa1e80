"""Covariances of point neighbourhoods: the inner loop of the surface normals.

:func:`nbcalib.registration.orientation.point_normals` finds each point's ``k`` nearest
neighbours with a KD-tree and takes the normal as the eigenvector of the smallest eigenvalue of
the neighbourhood's covariance. Gathering the neighbours into an (N, k, 3) array and contracting
it with ``einsum`` cost more than the eigen-decomposition (1.5 s against 0.7 s for 500 000
points); this kernel sums each neighbourhood in place instead.

The slow, readable reference is :func:`nbcalib.reference.normals.neighbourhood_covariances`.
"""

from __future__ import annotations

import numpy as np

from nbcalib.kernels._jit import jit

__all__ = ["neighbourhood_covariances"]


@jit
def _scatter3(points, idx, n):
    """Mean and scatter matrix of the ``n`` points ``points[idx[:n]]``.

    Returns (mx, my, mz, sxx, sxy, sxz, syy, syz, szz): the scatter is the sum of
    (p - mean)(p - mean)^T, not divided by ``n``. Shared by the normals and CT-ICP's planes.
    """
    mx = my = mz = 0.0
    for j in range(n):
        r = idx[j]
        mx += points[r, 0]
        my += points[r, 1]
        mz += points[r, 2]
    mx /= n
    my /= n
    mz /= n
    sxx = sxy = sxz = syy = syz = szz = 0.0
    for j in range(n):
        r = idx[j]
        dx = points[r, 0] - mx
        dy = points[r, 1] - my
        dz = points[r, 2] - mz
        sxx += dx * dx
        sxy += dx * dy
        sxz += dx * dz
        syy += dy * dy
        syz += dy * dz
        szz += dz * dz
    return mx, my, mz, sxx, sxy, sxz, syy, syz, szz


@jit
def _neighbourhood_covariances_impl(points, neighbours, out):
    """out[i] = sum over j of (p_j - mean)(p_j - mean)^T, j in neighbours[i] (not divided by k)."""
    n, k = neighbours.shape
    for i in range(n):
        _, _, _, sxx, sxy, sxz, syy, syz, szz = _scatter3(points, neighbours[i], k)
        out[i, 0, 0] = sxx
        out[i, 0, 1] = sxy
        out[i, 0, 2] = sxz
        out[i, 1, 0] = sxy
        out[i, 1, 1] = syy
        out[i, 1, 2] = syz
        out[i, 2, 0] = sxz
        out[i, 2, 1] = syz
        out[i, 2, 2] = szz


def neighbourhood_covariances(points, neighbours, out=None) -> np.ndarray:
    """Scatter matrix of each point's neighbourhood about its mean.

    Parameters
    ----------
    points : ndarray of shape (M, 3), float64
        All points (finite).
    neighbours : ndarray of shape (N, k), integer
        Rows of ``points`` forming each neighbourhood (k >= 1), e.g. a KD-tree's ``k`` nearest.
    out : ndarray of shape (N, 3, 3), float64, optional
        Written in place and returned.

    Returns
    -------
    ndarray of shape (N, 3, 3), float64
        ``sum_j (p_j - mean)(p_j - mean)^T`` (not divided by ``k``: the eigenvectors are the
        same).
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (M, 3), got {pts.shape}")
    nb = np.ascontiguousarray(neighbours)
    if nb.ndim != 2 or nb.shape[1] < 1 or not np.issubdtype(nb.dtype, np.integer):
        raise ValueError(
            f"neighbours must be an (N, k >= 1) integer array, got {nb.shape} {nb.dtype}"
        )
    nb = nb.astype(np.int64, copy=False)
    if nb.size and (nb.min() < 0 or nb.max() >= len(pts)):
        raise ValueError(f"neighbours must index the {len(pts)} points")
    if out is None:
        out = np.empty((nb.shape[0], 3, 3))
    elif out.shape != (nb.shape[0], 3, 3) or out.dtype != np.float64 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float64 array of shape ({nb.shape[0]}, 3, 3)")
    _neighbourhood_covariances_impl(pts, nb, out)
    return out
