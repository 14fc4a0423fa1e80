"""Bounding volume hierarchy over a scene's primitives (surface area heuristic).

:func:`build_bvh` packs the hierarchy into the flat arrays the ray casting kernels of
:mod:`nbcalib.kernels.raycast` walk (``Scene.bvh_bounds``, ``bvh_nodes``, ``bvh_order``);
:func:`primitive_bounds` gives each primitive's axis-aligned world box.
"""

from __future__ import annotations

import numpy as np

from nbcalib.kernels import raycast as _rc

__all__ = ["build_bvh", "primitive_bounds"]


def primitive_bounds(prims) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned world boxes ``(lo, hi)``, each ``(P, 3)``, enclosing every primitive."""
    prims = np.asarray(prims, dtype=np.float64)
    center = prims[:, _rc.PRIM_CENTER : _rc.PRIM_CENTER + 3]
    rows = prims[:, _rc.PRIM_AXES : _rc.PRIM_AXES + 9].reshape(-1, 3, 3)
    half = prims[:, _rc.PRIM_HALF : _rc.PRIM_HALF + 3]
    # extent along world k of sum_j h_j axis_j: sum_j |axis_j[k]| h_j
    extent = np.einsum("pjk,pj->pk", np.abs(rows), half)
    pad = 1e-6 * (1.0 + np.abs(center).max(axis=1, keepdims=True))
    return center - extent - pad, center + extent + pad


def _area(lo, hi):
    """Surface areas of boxes ``(lo, hi)`` of shape (..., 3)."""
    d = np.maximum(hi - lo, 0.0)
    return 2.0 * (d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0])


def _best_split(lo, hi, centroid):
    """Surface-area-heuristic split of a set of boxes: ``(cost, order, count_left)``.

    For each axis, the boxes sorted by centroid are split at every position; the cost of a
    split is ``area(left) * n_left + area(right) * n_right`` (expected intersection tests).
    """
    n = len(lo)
    best = (np.inf, None, 0)
    for axis in range(3):
        order = np.argsort(centroid[:, axis], kind="stable")
        l_lo = np.minimum.accumulate(lo[order], axis=0)
        l_hi = np.maximum.accumulate(hi[order], axis=0)
        r_lo = np.minimum.accumulate(lo[order][::-1], axis=0)[::-1]
        r_hi = np.maximum.accumulate(hi[order][::-1], axis=0)[::-1]
        counts = np.arange(1, n)
        cost = _area(l_lo[:-1], l_hi[:-1]) * counts + _area(r_lo[1:], r_hi[1:]) * (n - counts)
        k = int(np.argmin(cost))
        if cost[k] < best[0]:
            best = (float(cost[k]), order, k + 1)
    return best


def build_bvh(prims, *, leaf_size: int = 1):
    """Bounding volume hierarchy over the primitives, split by the surface area heuristic.

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The primitives.
    leaf_size : int
        Leaves hold at most this many primitives (more only when no split helps).

    Returns
    -------
    bounds : ndarray of shape (K, 6), float64
        Node boxes ``(min xyz, max xyz)``, world frame.
    nodes : ndarray of shape (K, 3), int64
        ``(first child, first primitive, primitive count)`` per node; root = node 0.
    order : ndarray of shape (P,), int64
        Primitive indices in leaf order.
    """
    lo, hi = primitive_bounds(prims)
    centroid = 0.5 * (lo + hi)
    bounds: list[np.ndarray] = [np.zeros(6)]
    nodes: list[list[int]] = [[0, 0, 0]]
    order: list[int] = []

    def fill(node: int, members: np.ndarray) -> None:
        box_lo, box_hi = lo[members].min(axis=0), hi[members].max(axis=0)
        bounds[node] = np.concatenate([box_lo, box_hi])
        if len(members) > leaf_size:
            cost, sorted_idx, n_left = _best_split(lo[members], hi[members], centroid[members])
            # split when descending (two box tests, then the children's expected primitive
            # tests) is cheaper than testing every member, and always for large sets
            area = _area(box_lo, box_hi)
            if cost + 2.0 * area < len(members) * area or len(members) > 8:
                members = members[sorted_idx]
                first = len(nodes)
                bounds.extend([np.zeros(6), np.zeros(6)])
                nodes.extend([[0, 0, 0], [0, 0, 0]])
                nodes[node] = [first, 0, 0]
                fill(first, members[:n_left])
                fill(first + 1, members[n_left:])
                return
        nodes[node] = [-1, len(order), len(members)]
        order.extend(int(m) for m in members)

    fill(0, np.arange(len(prims)))
    return (
        np.ascontiguousarray(np.stack(bounds)),
        np.ascontiguousarray(np.array(nodes, dtype=np.int64)),
        np.ascontiguousarray(np.array(order, dtype=np.int64)),
    )
