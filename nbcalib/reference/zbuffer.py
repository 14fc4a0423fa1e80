"""Slow, readable reference of the z-buffer kernels in :mod:`nbcalib.kernels.zbuffer`.

One plain Python loop over the points, one pixel at a time. It defines the semantics the kernels
must reproduce bit for bit: transform written out term by term, nearest pixel
``floor(u + 0.5)``, image ``[-0.5, W - 0.5) x [-0.5, H - 0.5)``, depth key = squared range in the
camera frame, the larger point index wins a tie, empty pixels hold -1 and inf.

The projection itself is the camera kernel :func:`nbcalib.kernels.projection.project_point`
(called from Python here), which has its own reference in :mod:`nbcalib.reference.camera`; this
module is about what happens after the projection.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels.projection import project_point

__all__ = ["render_zbuffer", "visible_mask"]


def _pixel_and_range2(model_id, params, T, point, width, height):
    """Flat pixel index (or -1) and squared range of one point, as the kernel computes them."""
    x, y, z = (float(c) for c in point)
    X = float(T[0, 0]) * x + float(T[0, 1]) * y + float(T[0, 2]) * z + float(T[0, 3])
    Y = float(T[1, 0]) * x + float(T[1, 1]) * y + float(T[1, 2]) * z + float(T[1, 3])
    Z = float(T[2, 0]) * x + float(T[2, 1]) * y + float(T[2, 2]) * z + float(T[2, 3])
    u, v, ok = project_point(model_id, params, X, Y, Z)
    if not ok:
        return -1, math.inf
    col = math.floor(u + 0.5)
    row = math.floor(v + 0.5)
    if not (0 <= col < width and 0 <= row < height):
        return -1, math.inf
    range2 = X * X + Y * Y + Z * Z
    if math.isinf(range2):
        return -1, math.inf
    return row * width + col, range2


def render_zbuffer(model_id, params, T_camera_b, points_b, width, height):
    """Nearest point per pixel, the slow way.

    Parameters
    ----------
    model_id : int
        ``camera.model_id``.
    params : ndarray of shape (16,), float64
        ``camera.params``.
    T_camera_b : ndarray of shape (4, 4), float64
        Transform from the points' frame to the camera frame.
    points_b : ndarray of shape (N, 3), float64
        Points in frame ``b``, metres (NaN rows allowed: they are skipped).
    width, height : int
        Image size in pixels.

    Returns
    -------
    range2 : ndarray of shape (H, W), float64
        Squared range of the nearest point per pixel, inf where empty.
    index : ndarray of shape (H, W), int32
        Row of that point in ``points_b``, -1 where empty.
    pixel : ndarray of shape (N,), int64
        Flat pixel ``row * W + col`` of each point, -1 if it has none.
    point_range2 : ndarray of shape (N,), float64
        Squared range of each point, inf if it has no pixel.
    """
    n = len(points_b)
    best = [math.inf] * (width * height)
    index = [-1] * (width * height)
    pixel = np.full(n, -1, dtype=np.int64)
    point_range2 = np.full(n, math.inf)
    for i in range(n):
        p, r2 = _pixel_and_range2(model_id, params, T_camera_b, points_b[i], width, height)
        pixel[i], point_range2[i] = p, r2
        if p < 0:
            continue
        # equal keys: the later (larger) index replaces the earlier one
        if r2 <= best[p]:
            best[p] = r2
            index[p] = i
    return (
        np.array(best, dtype=np.float64).reshape(height, width),
        np.array(index, dtype=np.int32).reshape(height, width),
        pixel,
        point_range2,
    )


def visible_mask(model_id, params, T_camera_b, points_b, width, height, margin, window):
    """Points not hidden behind nearer ones, the slow way.

    A point is visible when it has a pixel and its range is at most the smallest range found in
    the ``(2 window + 1)^2`` pixels around its own (clipped at the image border) plus ``margin``.

    Returns
    -------
    ndarray of shape (N,), bool
    """
    range2, _, pixel, point_range2 = render_zbuffer(
        model_id, params, T_camera_b, points_b, width, height
    )
    min_range = np.sqrt(range2)
    visible = np.zeros(len(points_b), dtype=bool)
    for i, p in enumerate(pixel):
        if p < 0:
            continue
        row, col = divmod(int(p), width)
        nearest = math.inf
        for r in range(max(row - window, 0), min(row + window + 1, height)):
            for c in range(max(col - window, 0), min(col + window + 1, width)):
                nearest = min(nearest, float(min_range[r, c]))
        visible[i] = math.sqrt(point_range2[i]) <= nearest + margin
    return visible
