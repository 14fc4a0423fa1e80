"""The regional NID: one joint histogram per region of the image, the mean of their NIDs.

``cost = "regional"`` (:mod:`nbcalib.registration.costs`). Why: a single joint histogram asks
one mapping from LiDAR intensity to image brightness to hold over the whole image, but what
links the two changes from place to place: the camera's shading (the light on a wall, on the
floor, the lamp's falloff, shadows) and the LiDAR's falloff with range and incidence are smooth
fields of their own, and materials map differently in each sensor. Matching those fields to
each other buys a single histogram information the true pose does not have: started at the
ground truth of the synthetic rig, a whole-image NID walked 1-47 cm away, and with the camera's
shading or the LiDAR's falloff switched off it stayed (docs/BENCHMARKS.md, section 5.7). Within a
small region both fields are nearly constant and one mapping holds; the mean of the regions'
NIDs is the conditional NID given the region (Loeckx et al., "Nonrigid image registration using
conditional mutual information", IEEE TMI 2010).

The regions are fixed at the anchor pose (the start of each outer iteration), as the visible
points are: the points the camera sees there are split by recursive median cuts of their
pixel coordinates (the longer side of each box first) until a region would have fewer than
``2 * region_points`` points. So every region holds ``region_points`` to twice that, whatever
the camera model, the image size or the part of the image the LiDAR covers; a dense cloud gets
hundreds of small regions, a single real scan a handful. Each region keeps its points while
the pose moves within the outer iteration (its histogram's support cannot be emptied by moving
points into another region), and its weight is its share of the points at the anchor.
"""

from __future__ import annotations

import numpy as np

from nbcalib.registration.nid import GroupedNIDCost

__all__ = ["median_cut_regions", "terms"]


def terms(view, config) -> list:
    """``[(GroupedNIDCost, 1.0)]``: the pair's regions and their histograms."""
    uv, valid = view.anchor_pixels()
    regions = median_cut_regions(np.where(valid[:, None], uv, 0.0), config.region_points)
    cost = GroupedNIDCost(
        view.camera,
        view.image,
        view.points,
        view.intensities,
        regions,
        bins=config.bins,
        form=view.form,
        parallel=config.parallel,
        level=view.level,
    )
    return [(cost, 1.0)]


def median_cut_regions(pixels, region_points: int) -> np.ndarray:
    """Region of each pixel: recursive median cuts into regions of ``region_points`` to twice that.

    Parameters
    ----------
    pixels : ndarray of shape (N, 2), float
        Pixel coordinates ``(u, v)``.
    region_points : int
        Fewest points of a region (>= 1); a box with fewer than twice this is not cut. Fewer
        than ``2 * region_points`` points in all make one region.

    Returns
    -------
    ndarray of shape (N,), int64
        Region ids ``0 .. R - 1``; a region is a box of the image, cut along its longer side at
        the median (ties broken by the points' order, so the result is deterministic). The
        numba kernel :mod:`nbcalib.kernels.regions`; its reference
        :func:`nbcalib.reference.regions.median_cut_regions`.
    """
    from nbcalib.kernels import regions as kernel

    uv = np.asarray(pixels, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"pixels must have shape (N, 2), got {uv.shape}")
    if region_points < 1:
        raise ValueError(f"region_points must be >= 1, got {region_points}")
    if not np.all(np.isfinite(uv)):
        raise ValueError("pixels must be finite")
    return kernel.median_cut_regions(uv, int(region_points))
