"""Z-buffer kernels: render points into a camera's pixel grid, keep the nearest point per pixel.

Semantics (shared with the slow reference :mod:`nbcalib.reference.zbuffer`, bit for bit):

- A point ``p`` (row ``i`` of ``points``, any frame ``b``) is moved into the camera frame with the
  4 x 4 ``T_camera_b`` as ``X = T[0, 0] x + T[0, 1] y + T[0, 2] z + T[0, 3]`` (same for ``Y``,
  ``Z``), written out in this order, and projected with
  :func:`nbcalib.kernels.projection.project_point`.
- Invalid projections (non-finite points, behind the camera, outside the model's domain) are
  skipped; so are points whose pixel ``(floor(u + 0.5), floor(v + 0.5))`` is off the image
  (docs/conventions.md section 6: the image spans ``[-0.5, W - 0.5) x [-0.5, H - 0.5)``) and
  points whose squared range overflows to inf.
- The depth key is the **squared range** ``X^2 + Y^2 + Z^2`` in the camera frame (as the
  reference toolbox), float64.
- **Tie rule**: among points with the same key in one pixel, the larger point index wins. A serial
  loop in index order with ``<=`` does exactly this; it is also the reference toolbox's
  last-writer-wins for its serial loop, and it is an order-free rule that a parallel scatter could
  reproduce.
- Empty pixels: index ``-1``, squared range ``inf``.

The work is split in two kernels so that hidden-point removal
(:func:`nbcalib.preprocess.lidar_image.visible_mask`) can reuse the per-point pixels:

1. :func:`_project_to_pixels` (per point, independent): flat pixel ``row * W + col`` or -1, and
   the squared range. Its body is written with ``prange`` so that ``benchmarks/bench_zbuffer.py``
   can compile a parallel twin (each point writes only its own slots, so the twin equals it
   exactly); nbcalib runs it serially because the twin showed no gain on the 2-core machine
   (docs/BENCHMARKS.md).
2. :func:`_scatter_nearest` (serial): the z-buffer proper.

Two passes rather than one fused loop: a fused loop was 2.5 to 4 times slower
(docs/BENCHMARKS.md), most likely because the scatter's random accesses to the (H * W) buffers
miss the caches, and a tight loop overlaps the misses while a fused one waits for each behind
the projection arithmetic.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit
from nbcalib.kernels.projection import project_point


@jit
def _pixel_of_point(model_id, params, T, x, y, z, width, height):
    """Flat pixel index (or -1) and squared camera-frame range of one point."""
    X = T[0, 0] * x + T[0, 1] * y + T[0, 2] * z + T[0, 3]
    Y = T[1, 0] * x + T[1, 1] * y + T[1, 2] * z + T[1, 3]
    Z = T[2, 0] * x + T[2, 1] * y + T[2, 2] * z + T[2, 3]
    u, v, ok = project_point(model_id, params, X, Y, Z)
    if not ok:
        return -1, math.inf
    col = np.floor(u + 0.5)
    row = np.floor(v + 0.5)
    if not (col >= 0.0 and col < width and row >= 0.0 and row < height):
        return -1, math.inf
    range2 = X * X + Y * Y + Z * Z
    if not range2 < math.inf:
        return -1, math.inf
    return int(row) * width + int(col), range2


def _project_to_pixels_impl(model_id, params, T, points, width, height, pixel, range2):
    for i in prange(points.shape[0]):
        p, r2 = _pixel_of_point(
            model_id, params, T, points[i, 0], points[i, 1], points[i, 2], width, height
        )
        pixel[i] = p
        range2[i] = r2


#: Per-point pixels and squared ranges. Writes ``pixel`` (int64, -1 = none) and ``range2``
#: (float64, inf = none), both of shape (N,).
_project_to_pixels = jit(_project_to_pixels_impl)


@jit
def _scatter_nearest(pixel, range2, best_range2, index):
    """Keep the nearest point per pixel; on equal keys the larger index wins.

    ``best_range2`` (float64, inf-filled) and ``index`` (int32, -1-filled) are flat (H * W,)
    buffers, updated in place.
    """
    for i in range(pixel.shape[0]):
        p = pixel[i]
        if p >= 0 and range2[i] <= best_range2[p]:
            best_range2[p] = range2[i]
            index[p] = i


@jit
def _range_map(best_range2, out):
    """Float32 range (metres) from squared ranges; inf stays inf."""
    for p in range(best_range2.shape[0]):
        out[p] = np.float32(math.sqrt(best_range2[p]))


@jit
def _min_filter(image, half):
    """Minimum over the (2 half + 1)^2 window around each pixel, clipped at the borders.

    Separable (rows, then columns): exact for a minimum. ``image`` is float64 (H, W).
    """
    height, width = image.shape
    tmp = np.empty_like(image)
    for r in range(height):
        for c in range(width):
            m = image[r, c]
            for cc in range(max(c - half, 0), min(c + half + 1, width)):
                if image[r, cc] < m:
                    m = image[r, cc]
            tmp[r, c] = m
    out = np.empty_like(image)
    for r in range(height):
        for c in range(width):
            m = tmp[r, c]
            for rr in range(max(r - half, 0), min(r + half + 1, height)):
                if tmp[rr, c] < m:
                    m = tmp[rr, c]
            out[r, c] = m
    return out


@jit
def _visible(pixel, range2, min_range_flat, margin, out):
    """``out[i]`` = point ``i`` has a pixel and ``range <= min_range[pixel] + margin``."""
    for i in range(pixel.shape[0]):
        p = pixel[i]
        out[i] = p >= 0 and math.sqrt(range2[i]) <= min_range_flat[p] + margin
