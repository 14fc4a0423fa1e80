"""The intensity NID of the paper: one joint histogram per pair, or one per orientation class.

``cost = "nid"`` (:mod:`nbcalib.registration.costs`). The paper and the reference toolbox
histogram every point of a pair together. With ``orientation_classes`` (default) the points
are split by the dominant axis of their surface normal and the pair's term is the point-weighted
mean of the class NIDs (:mod:`nbcalib.registration.orientation`): within a class, shading is
nearly constant. A pair whose smallest class has fewer than ``min_class_points`` visible points
keeps one histogram (all or nothing: a class too small for its own histogram would have to
join another and bring its shading along).
"""

from __future__ import annotations

import numpy as np

from nbcalib.registration.nid import NIDCost

__all__ = ["class_groups", "terms"]


def terms(view, config) -> list:
    """``[(NIDCost, weight)]`` of one pair: one per orientation class, or one."""
    keep = view.keep
    groups = (
        class_groups(view.pair, keep, config, scale=view.n_visible / max(keep.size, 1))
        if config.orientation_classes
        else [keep]
    )
    out = []
    for group in groups:
        points, intensities = view.pair.rows(group)
        cost = NIDCost(
            view.camera,
            view.image,
            points,
            intensities,
            bins=config.bins,
            form=view.form,
            parallel=config.parallel,
            level=view.level,
        )
        out.append((cost, group.size / keep.size if keep.size else 1.0))
    return out


def class_groups(pair, keep: np.ndarray, config, scale=1.0) -> list[np.ndarray]:
    """``keep`` split by orientation class, or whole when a class has under ``min_class_points``.

    The groups keep the pixel order of ``keep``. ``scale``: visible points per point of
    ``keep`` (a subset), so that a subset decides as all of them would.
    """
    classes = pair.orientation_classes(keep)
    sizes = np.bincount(classes, minlength=3)
    if scale * sizes.min() < config.min_class_points:
        return [keep]
    return [keep[classes == c] for c in range(len(sizes))]
