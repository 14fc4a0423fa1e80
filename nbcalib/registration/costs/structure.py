"""The structure term: the NID between LiDAR depth edges and image edges.

Added to each pair's intensity term with the weight ``structure_weight`` (0, off, by default;
:mod:`nbcalib.registration.costs`). The depth-edge score of each point and the image's edge
strength come from :mod:`nbcalib.registration.structure`, made once per pair
(:meth:`~nbcalib.registration.pair.RegistrationPair.structure`).
"""

from __future__ import annotations

from nbcalib.registration.nid import NIDCost

__all__ = ["terms"]


def terms(view, config) -> list:
    """``[(NIDCost, 1.0)]``: the pair's depth-edge scores against its image's edges."""
    from nbcalib.registration.pair import downscale_image

    scores, edges = view.pair.structure()
    cost = NIDCost(
        view.camera,
        downscale_image(edges, view.level, equalize=False),
        view.points,
        scores[view.keep],
        bins=config.bins,
        form=view.form,
        parallel=config.parallel,
        level=view.level,
    )
    return [(cost, 1.0)]
