"""2D-3D correspondences: camera keypoints paired with dense-cloud points through the index map.

A match pairs a camera keypoint with a LiDAR-image keypoint. The LiDAR image was rendered from
the dense cloud by a virtual camera with a z-buffer, and its index map tells, per pixel, which
cloud point is shown there (-1 where nothing is). Lifting a LiDAR keypoint ``(u, v)``:

1. its nearest pixel ``(floor(u + 0.5), floor(v + 0.5))`` (docs/conventions.md section 6);
2. if that pixel is empty (or off the image), the filled pixel whose centre is nearest to
   ``(u, v)`` within ``search_radius`` pixels; on equal distances the first in the order
   (distance from the nearest pixel, then row offset, then column offset);
3. otherwise the match is dropped.

*Differs from the reference toolbox*, which truncates the keypoint to ``int(u)`` and whose
neighbour fallback never runs (a misplaced ``continue``), so it keeps only keypoints that land on
a filled pixel (reference_toolbox.md sections 1.4 and 9). The LiDAR image has holes between scan
lines, and a learned matcher puts keypoints on edges, next to holes; the fallback recovers them.

Correspondences of several pairs (bags) are pooled: the extrinsic is the same for all.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Correspondences",
    "correspondences_from_matches",
    "lift_lidar_pixels",
    "lift_matches",
    "pool_correspondences",
]


@dataclass(frozen=True)
class Correspondences:
    """2D-3D correspondences, possibly pooled over pairs.

    Attributes
    ----------
    uv_camera : ndarray of shape (M, 2), float64
        Camera keypoints, pixels (u = column, v = row).
    points_lidar : ndarray of shape (M, 3), float64
        Their 3-D points in the LiDAR frame, metres.
    uv_lidar : ndarray of shape (M, 2), float64
        The LiDAR-image keypoints they were lifted from (NaN for explicit 3-D points).
    point_index : ndarray of shape (M,), int64
        Row of each point in its pair's dense cloud (-1 for explicit 3-D points).
    pair : ndarray of shape (M,), int64
        Index into ``names`` of the pair each correspondence comes from.
    names : tuple of str
        Data names of the pairs.
    n_matches : int
        Matches offered before lifting (those that found no point were dropped).
    confidence : ndarray of shape (M,), float64 or None
        The matcher's score of each correspondence (higher is better); None means all 1
        (manual picks). See :attr:`weights`.
    """

    uv_camera: np.ndarray
    points_lidar: np.ndarray
    uv_lidar: np.ndarray
    point_index: np.ndarray
    pair: np.ndarray
    names: tuple[str, ...] = ()
    n_matches: int = 0
    confidence: np.ndarray | None = None

    @property
    def weights(self) -> np.ndarray:
        """Confidences as non-negative weights (all 1 without confidences), shape (M,)."""
        if self.confidence is None:
            return np.ones(len(self))
        return np.clip(np.nan_to_num(self.confidence, nan=0.0), 0.0, None)

    def __len__(self) -> int:
        return len(self.uv_camera)

    def count_per_pair(self) -> dict[str, int]:
        """Correspondences of each pair, by name."""
        counts = np.bincount(self.pair, minlength=len(self.names))
        return {name: int(c) for name, c in zip(self.names, counts)}

    @classmethod
    def empty(cls, names: Sequence[str] = ()) -> Correspondences:
        """No correspondences."""
        return cls(
            np.empty((0, 2)),
            np.empty((0, 3)),
            np.empty((0, 2)),
            np.empty(0, dtype=np.int64),
            np.empty(0, dtype=np.int64),
            tuple(names),
            0,
            None,
        )


def _neighbour_offsets(radius: float) -> np.ndarray:
    """Integer (dv, du) offsets within ``radius + 1`` of 0, nearest first, then by (dv, du)."""
    reach = math.ceil(radius) + 1
    dv, du = np.mgrid[-reach : reach + 1, -reach : reach + 1]
    dv, du = dv.ravel(), du.ravel()
    d2 = dv * dv + du * du
    keep = d2 <= (radius + 1.0) ** 2
    order = np.lexsort((du[keep], dv[keep], d2[keep]))
    return np.stack([dv[keep][order], du[keep][order]], axis=1)


def lift_lidar_pixels(uv_lidar, index_map, *, search_radius: float = 2.0) -> np.ndarray:
    """Cloud point shown at (or next to) each LiDAR-image keypoint (module docstring).

    Parameters
    ----------
    uv_lidar : array_like of shape (K, 2)
        LiDAR-image keypoints, pixels (u = column, v = row).
    index_map : array_like of shape (H, W), integer
        Cloud row per pixel, -1 where empty (``<name>_lidar_indices.png``).
    search_radius : float, optional
        Largest distance, pixels, from the keypoint to a filled pixel's centre used when its
        own pixel is empty; 0 keeps only keypoints on filled pixels.

    Returns
    -------
    ndarray of shape (K,), int64
        Cloud row of each keypoint, -1 where none was found.
    """
    uv = np.asarray(uv_lidar, dtype=np.float64).reshape(-1, 2)
    index = np.asarray(index_map)
    if index.ndim != 2 or index.dtype.kind not in "iu":
        raise ValueError(f"index_map must be an (H, W) integer array, got {index.dtype}")
    if not np.all(np.isfinite(uv)):
        raise ValueError("uv_lidar must be finite")
    if not (math.isfinite(search_radius) and search_radius >= 0.0):
        raise ValueError(f"search_radius must be >= 0 pixels, got {search_radius}")
    height, width = index.shape
    col0 = np.floor(uv[:, 0] + 0.5).astype(np.int64)
    row0 = np.floor(uv[:, 1] + 0.5).astype(np.int64)
    offsets = _neighbour_offsets(search_radius)
    rows = row0[:, None] + offsets[None, :, 0]
    cols = col0[:, None] + offsets[None, :, 1]
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    values = np.full(rows.shape, -1, dtype=np.int64)
    values[inside] = index[rows[inside], cols[inside]]
    d2 = (cols - uv[:, 0:1]) ** 2 + (rows - uv[:, 1:2]) ** 2
    own = np.zeros(offsets.shape[0], dtype=bool)
    own[0] = True  # the nearest pixel itself needs no radius
    ok = (values >= 0) & ((d2 <= search_radius**2) | own[None, :])
    d2 = np.where(ok, d2, np.inf)
    if d2.shape[1] and d2.shape[0]:
        best = np.argmin(d2, axis=1)  # first of equal distances: the offset order
        found = np.isfinite(d2[np.arange(len(uv)), best])
        return np.where(found, values[np.arange(len(uv)), best], -1)
    return np.full(len(uv), -1, dtype=np.int64)


def lift_matches(
    uv_camera,
    uv_lidar,
    index_map,
    points_lidar,
    *,
    search_radius: float = 2.0,
    name: str = "",
    confidence=None,
) -> Correspondences:
    """Lift matched keypoint pairs to 2D-3D correspondences through the index map.

    Parameters
    ----------
    uv_camera : array_like of shape (S, 2)
        Matched camera keypoints, pixels.
    uv_lidar : array_like of shape (S, 2)
        Their LiDAR-image keypoints, pixels.
    index_map : array_like of shape (H, W), integer
        The pair's index map (-1 empty).
    points_lidar : array_like of shape (N, 3)
        The pair's dense cloud, LiDAR frame, metres (rows named by the index map).
    search_radius : float, optional
        See :func:`lift_lidar_pixels`.
    name : str, optional
        Data name of the pair.
    confidence : array_like of shape (S,), optional
        The matcher's score of each match, kept for the correspondences that are lifted.

    Returns
    -------
    Correspondences
        The matches that found a point (``n_matches`` = S).
    """
    uv_c = np.asarray(uv_camera, dtype=np.float64).reshape(-1, 2)
    uv_l = np.asarray(uv_lidar, dtype=np.float64).reshape(-1, 2)
    points = np.asarray(points_lidar, dtype=np.float64)
    if uv_c.shape != uv_l.shape:
        raise ValueError(f"uv_camera and uv_lidar differ in shape: {uv_c.shape}, {uv_l.shape}")
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_lidar must have shape (N, 3), got {points.shape}")
    rows = lift_lidar_pixels(uv_l, index_map, search_radius=search_radius)
    if rows.size and rows.max() >= len(points):
        raise ValueError(f"the index map refers to point {rows.max()}, the cloud has {len(points)}")
    found = rows >= 0
    point_rows = rows[found]
    if confidence is not None:
        confidence = np.asarray(confidence, dtype=np.float64).reshape(-1)
        if confidence.shape != (len(uv_c),):
            raise ValueError(f"confidence must have shape ({len(uv_c)},), got {confidence.shape}")
        confidence = confidence[found]
    return Correspondences(
        uv_camera=uv_c[found],
        points_lidar=points[point_rows],
        uv_lidar=uv_l[found],
        point_index=point_rows,
        pair=np.zeros(len(point_rows), dtype=np.int64),
        names=(name,),
        n_matches=len(uv_c),
        confidence=confidence,
    )


def correspondences_from_matches(
    matches, index_map, points_lidar, *, search_radius: float = 2.0, name: str = ""
) -> Correspondences:
    """Lift a :class:`nbcalib.matching.matches.Matches` (a ``<name>_matches.json``).

    The match confidences are kept (:attr:`Correspondences.confidence`). See
    :func:`lift_matches` for the parameters.
    """
    uv_camera, uv_lidar, confidence = matches.matched()
    return lift_matches(
        uv_camera,
        uv_lidar,
        index_map,
        points_lidar,
        search_radius=search_radius,
        name=name,
        confidence=confidence,
    )


def pool_correspondences(parts: Sequence[Correspondences]) -> Correspondences:
    """Concatenate the correspondences of several pairs (the reference pools all bags).

    Parts with the same name are merged under one name.
    """
    names: list[str] = []
    pairs = []
    for part in parts:
        remap = []
        for name in part.names:
            if name not in names:
                names.append(name)
            remap.append(names.index(name))
        pairs.append(np.asarray(remap, dtype=np.int64)[part.pair] if len(part) else part.pair)
    if not parts:
        return Correspondences.empty()
    confidence = None
    if any(p.confidence is not None for p in parts):
        confidence = np.concatenate(
            [p.confidence if p.confidence is not None else np.ones(len(p)) for p in parts]
        )
    return Correspondences(
        uv_camera=np.concatenate([p.uv_camera for p in parts]),
        points_lidar=np.concatenate([p.points_lidar for p in parts]),
        uv_lidar=np.concatenate([p.uv_lidar for p in parts]),
        point_index=np.concatenate([p.point_index for p in parts]),
        pair=np.concatenate(pairs).astype(np.int64),
        names=tuple(names),
        n_matches=sum(p.n_matches for p in parts),
        confidence=confidence,
    )
