"""The structure channel: LiDAR depth edges against image edges, for a second NID term.

Why: the intensity NID compares LiDAR reflectivity with camera brightness, which share little on
real sensors (KITTI: NID 0.988 at the reference calibration). Both sensors, however, see the
*outlines* of objects: a LiDAR point in front of a range jump lies on an object's silhouette, and
the camera sees an edge there. Levinson and Thrun (RSS 2013) align the two with a product of edge
strengths; nbcalib compares them with the same NID as the intensities, so that no scale between
the two terms has to be tuned and the B-spline NID's exact gradient comes for free
(:func:`nbcalib.registration.costs.build_cost`, ``RefineConfig.structure_weight``).

- :func:`depth_edge_scores`: per point, how far its neighbours *along the scan direction* lie
  behind it (``max(r_neighbour - r, 0)``, clipped and square-rooted as Levinson and Thrun). The
  neighbours are found in the LiDAR's spherical view with elevation stretched, so they are the
  points of the same ring on a spinning LiDAR and the nearest points at about the same elevation
  on any other kind; a plain nearest-neighbour search would mark every ground point as an edge,
  since the next ring lies metres farther along the ground. It depends only on the cloud, not on
  the pose: computed once per pair.
- :func:`image_edges`: the Sobel gradient magnitude of the lightly smoothed grey image, smoothed
  again, normalised by its 99th percentile and square-rooted. It is not histogram-equalised:
  equalisation lifts the sensor noise of flat regions (sky, road) to the level of real edges.
"""

from __future__ import annotations

import numpy as np

__all__ = ["depth_edge_scores", "image_edges"]


def depth_edge_scores(
    points, *, neighbours: int = 5, clip: float = 2.0, elevation_scale: float = 10.0
) -> np.ndarray:
    """Foreground depth-discontinuity score of each point, in [0, 1].

    Parameters
    ----------
    points : ndarray of shape (N, 3)
        Cloud in the LiDAR frame, metres (non-finite points and points at the origin score 0).
    neighbours : int
        Neighbours compared, the point itself included.
    clip : float
        Range jump, metres, that scores 1.
    elevation_scale : float
        Stretch of the elevation axis in the neighbour search (module docstring).

    Returns
    -------
    ndarray of shape (N,), float64
        ``sqrt(min(max_j(r_j - r), clip) / clip)`` over the neighbours ``j``.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    if not clip > 0 or neighbours < 2:
        raise ValueError("clip must be > 0 and neighbours >= 2")
    scores = np.zeros(len(pts))
    r = np.linalg.norm(pts, axis=1)
    ok = np.flatnonzero(np.isfinite(r) & (r > 0))
    if ok.size < 2:
        return scores
    p, rr = pts[ok], r[ok]
    azimuth = np.arctan2(p[:, 1], p[:, 0])
    elevation = np.arcsin(np.clip(p[:, 2] / rr, -1.0, 1.0))
    view = np.column_stack(
        [
            np.cos(elevation) * np.cos(azimuth),
            np.cos(elevation) * np.sin(azimuth),
            elevation_scale * elevation,
        ]
    )
    k = int(min(neighbours, ok.size))
    _, idx = cKDTree(view).query(view, k=k, workers=-1)
    jump = np.clip((rr[idx] - rr[:, None]).max(axis=1), 0.0, clip)
    scores[ok] = np.sqrt(jump / clip)
    return scores


def image_edges(image, *, sigma: float = 1.0, blur: float = 1.0) -> np.ndarray:
    """Edge strength of a grey image as uint8 (module docstring).

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8, uint16 or float in [0, 1]
    sigma : float
        Gaussian smoothing before the Sobel filter, pixels.
    blur : float
        Gaussian smoothing of the gradient magnitude, pixels (0: none).

    Returns
    -------
    ndarray of shape (H, W), uint8
    """
    from scipy import ndimage

    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image must be a 2-D grey image, got shape {img.shape}")
    scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype, 1.0)
    smooth = ndimage.gaussian_filter(img.astype(np.float64) / scale, sigma)
    magnitude = np.hypot(ndimage.sobel(smooth, 1), ndimage.sobel(smooth, 0))
    if blur > 0:
        magnitude = ndimage.gaussian_filter(magnitude, blur)
    top = float(np.percentile(magnitude, 99))
    if not top > 0:
        return np.zeros(img.shape, dtype=np.uint8)
    return np.round(np.sqrt(np.clip(magnitude / top, 0.0, 1.0)) * 255.0).astype(np.uint8)
