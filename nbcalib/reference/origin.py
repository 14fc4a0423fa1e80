"""Slow reference of :mod:`nbcalib.kernels.origin`: a scan's ring spread from one origin."""

from __future__ import annotations

import numpy as np


def ring_spread(points, origin, *, width, group, u_max, min_distance) -> float:
    """The entropy of the elevation tangents in fine bins minus that in ``group``-bin sums.

    Weighted by the binned points' number, with ``log(group)`` for every point not binned.
    """
    q = np.asarray(points, dtype=np.float64) - np.asarray(origin, dtype=np.float64)
    n = len(q)
    d = np.hypot(q[:, 0], q[:, 1])
    q, d = q[d > min_distance], d[d > min_distance]
    u = q[:, 2] / d
    u = u[(u > -u_max) & (u < u_max)]
    n_fine = (round(2.0 * u_max / width) // group) * group
    bins = ((u + u_max) / width).astype(np.int64)
    fine = np.bincount(bins[bins < n_fine], minlength=n_fine).astype(np.float64)
    coarse = fine.reshape(-1, group).sum(axis=1)

    def entropy(h):
        p = h[h > 0] / h.sum()
        return float(-(p * np.log(p)).sum())

    binned = fine.sum()
    spread = entropy(fine) - entropy(coarse) if binned > 0 else 0.0
    # points not binned count as spread as far as can be
    return (binned * spread + (n - binned) * np.log(group)) / max(n, 1)
