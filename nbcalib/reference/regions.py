"""Reference of :mod:`nbcalib.kernels.regions`: recursive median cuts with NumPy, box by box."""

from __future__ import annotations

import numpy as np

__all__ = ["median_cut_regions"]


def median_cut_regions(pixels, region_points: int) -> np.ndarray:
    """Region of each pixel: boxes cut at the median of their longer side, recursively.

    A box with fewer than ``2 * region_points`` points is a region; otherwise it is sorted along
    its longer side (stable: ties keep the box's order) and split in two halves, the lower half
    cut first. Regions are numbered in the order they are found.
    """
    uv = np.asarray(pixels, dtype=np.float64)
    regions = np.zeros(len(uv), dtype=np.int64)
    stack = [np.arange(len(uv))]
    leaves = []
    while stack:
        idx = stack.pop()
        if idx.size < 2 * region_points:
            leaves.append(idx)
            continue
        span = uv[idx].max(axis=0) - uv[idx].min(axis=0)
        axis = int(np.argmax(span))
        order = idx[np.argsort(uv[idx, axis], kind="stable")]
        half = order.size // 2
        stack += [order[half:], order[:half]]
    for region, idx in enumerate(leaves):
        regions[idx] = region
    return regions
