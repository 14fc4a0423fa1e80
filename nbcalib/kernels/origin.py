"""Ring sharpness of a spinning LiDAR's scan seen from many candidate origins at once.

Semantics (shared with the slow reference :mod:`nbcalib.reference.origin`, to rounding):

- For a candidate origin ``(x, y, z)`` each point with horizontal distance ``d`` from ``(x, y)``
  above ``min_distance`` gets ``u = (p_z - z) / d``, the tangent of its elevation, which a beam
  of a level spinning LiDAR keeps whatever it hits; points with ``|u| >= u_max`` are not binned.
- ``u`` falls into the fine bin ``floor((u + u_max) / width)`` of ``n_fine`` (a multiple of
  ``group``); ``group`` consecutive fine bins make a coarse bin.
- The spread is the entropy (nats) of the fine histogram minus that of the coarse one: what the
  fine bins add within the coarse ones, 0 when every coarse bin holds one sharp ring. Points not
  binned count as spread as far as can be (``log(group)``): the spread is the binned points'
  spread and ``log(group)`` weighted by their numbers, so that a candidate cannot look sharp by
  seeing few points (a plug-in entropy of few points is low).
- Tangents rather than angles: a multiply instead of an ``atan2`` per point and candidate, and
  rings are as sharp in one as in the other.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels._jit import jit


@jit
def _entropy_difference(fine, group):
    """Entropy of ``fine`` minus that of its sums over ``group`` consecutive bins (nats)."""
    total = 0.0
    for k in range(fine.shape[0]):
        total += fine[k]
    if total <= 0.0:
        return 0.0
    h_fine = 0.0
    h_coarse = 0.0
    for c in range(fine.shape[0] // group):
        s = 0.0
        for k in range(c * group, (c + 1) * group):
            n = fine[k]
            if n > 0.0:
                p = n / total
                h_fine -= p * math.log(p)
                s += n
        if s > 0.0:
            p = s / total
            h_coarse -= p * math.log(p)
    return h_fine - h_coarse


@jit
def _ring_spreads(points, xs, ys, zs, width, n_fine, group, u_max, min_distance, out):
    """``out[i, j, k]``: the spread of ``points`` (N, 3) seen from ``(xs[i], ys[j], zs[k])``."""
    hist = np.zeros(n_fine)
    n = points.shape[0]
    inv_d = np.empty(n)
    most = math.log(group)
    for i in range(xs.shape[0]):
        for j in range(ys.shape[0]):
            for p in range(n):
                dx = points[p, 0] - xs[i]
                dy = points[p, 1] - ys[j]
                d = math.sqrt(dx * dx + dy * dy)
                inv_d[p] = 1.0 / d if d > min_distance else 0.0
            for k in range(zs.shape[0]):
                hist[:] = 0.0
                z = zs[k]
                binned = 0.0
                for p in range(n):
                    if inv_d[p] == 0.0:
                        continue
                    u = (points[p, 2] - z) * inv_d[p]
                    if u <= -u_max or u >= u_max:
                        continue
                    b = int((u + u_max) / width)
                    if b < n_fine:
                        hist[b] += 1.0
                        binned += 1.0
                spread = _entropy_difference(hist, group)
                out[i, j, k] = (binned * spread + (n - binned) * most) / max(n, 1)
