"""Surface-orientation classes of a dense cloud, for the orientation-conditioned NID.

Why: a camera sees albedo times shading, and shading depends on which way a surface faces
(light from above, the sky, a lamp on one wall). The LiDAR's intensity does not share that
shading, but both images still correlate with surface orientation (a floor is lit differently
from a wall, and a LiDAR returns weaker at grazing incidence). A single joint histogram over
all points mixes these orientation-driven statistics with the albedo texture, and shifting the
cloud so that floor points land on brighter or darker image regions buys information that the
true pose does not have: on the synthetic scenes the NID minimum sat 0.1-0.3 degrees off in
pitch, always the same way (docs/BENCHMARKS.md, "Orientation-conditioned NID").

Conditioning removes it: the points are split by the dominant axis of their surface normal (in
the LiDAR frame; three classes, sign ignored), each class gets its own joint histogram, and the
cost is the point-weighted mean of the class NIDs
(:mod:`nbcalib.registration.costs.nid`). Within a class, shading is nearly constant
and the histogram compares texture with texture.

Normals come from the principal axes of each point's ``k`` nearest neighbours (SciPy's KD-tree),
computed in chunks so that a few million points need tens of megabytes, not gigabytes, and only
for the points the camera sees (:meth:`nbcalib.registration.refine.RegistrationPair.
orientation_classes`): on a 360-degree cloud that is a fraction of the points. Voxel-based
normals (PCA per 6-15 cm voxel) are 20 x faster but agreed with these on only 75-86 % of the
demo scene's points, and lost most of the accuracy gain.
"""

from __future__ import annotations

import numpy as np

__all__ = ["CLASS_NAMES", "class_of_normals", "kdtree", "orientation_classes", "point_normals"]

#: Class ``c`` holds points whose normal is closest to LiDAR axis ``c`` (either sign).
CLASS_NAMES = ("x", "y", "z")

_CHUNK = 131072


def point_normals(points, *, k: int = 16, indices=None, tree=None, workers: int = -1):
    """Unit surface normals (sign arbitrary) from the ``k`` nearest neighbours of points.

    Parameters
    ----------
    points : ndarray of shape (N, 3), float
        Points, metres; N >= 3.
    k : int, optional
        Neighbours per point, the point itself included (clipped to N).
    indices : array_like of int, optional
        Only these points' normals (their neighbours come from all points); default all.
    tree : scipy.spatial.cKDTree, optional
        A KD-tree of ``points`` built before (:func:`kdtree`; about 0.2 s per million points).
    workers : int, optional
        Threads of the KD-tree query (-1: all).

    Returns
    -------
    ndarray of shape (len(indices), 3), float64
        The eigenvector of the smallest eigenvalue of each neighbourhood's covariance.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    if pts.shape[0] < 3:
        raise ValueError(f"normals need at least 3 points, got {pts.shape[0]}")
    if not np.all(np.isfinite(pts)):
        raise ValueError("points must be finite")
    from nbcalib.kernels.normals import neighbourhood_covariances

    k = int(min(max(k, 3), pts.shape[0]))
    tree = kdtree(pts) if tree is None else tree
    query = pts if indices is None else pts[np.asarray(indices, dtype=np.int64)]
    normals = np.empty_like(query)
    cov = np.empty((min(_CHUNK, query.shape[0]), 3, 3))
    for start in range(0, query.shape[0], _CHUNK):
        chunk = query[start : start + _CHUNK]
        _, idx = tree.query(chunk, k=k, workers=workers)
        scatter = neighbourhood_covariances(pts, idx, out=cov[: len(chunk)])
        normals[start : start + _CHUNK] = np.linalg.eigh(scatter)[1][:, :, 0]
    return normals


def kdtree(points):
    """SciPy's KD-tree of ``points`` for neighbour queries, built the fast way.

    The sliding-midpoint tree (``balanced_tree=False``, no node shrinking) builds in 0.5 s
    instead of 1.4 s for 2.3 M points of a dense Livox cloud and answers its 16-nearest queries
    15 % faster; the neighbours are the same (docs/BENCHMARKS.md, section 10).
    """
    from scipy.spatial import cKDTree

    return cKDTree(points, balanced_tree=False, compact_nodes=False)


def orientation_classes(points, *, k: int = 16) -> np.ndarray:
    """Orientation class of each point: the LiDAR axis its normal is closest to (0, 1, 2).

    Parameters
    ----------
    points : ndarray of shape (N, 3), float
        Dense cloud in the LiDAR frame, metres (N >= 3).
    k : int, optional
        Neighbours of the normal estimate.

    Returns
    -------
    ndarray of shape (N,), int8
    """
    return class_of_normals(point_normals(points, k=k))


def class_of_normals(normals) -> np.ndarray:
    """The LiDAR axis (0, 1, 2) each normal is closest to, either sign, int8."""
    return np.argmax(np.abs(np.asarray(normals)), axis=1).astype(np.int8)
