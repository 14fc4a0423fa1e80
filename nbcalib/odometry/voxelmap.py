"""Voxel grids of the odometry: downsampling, the output accumulator and the local map.

Public wrappers of :mod:`nbcalib.kernels.voxelmap`, whose docstring gives the semantics (voxel
keys ``floor(p / voxel_size)``, voxels numbered in order of first appearance); the slow
references are in :mod:`nbcalib.reference.integrate`.

- :func:`voxel_downsample`, :func:`stratified_downsample`: the points a registration uses;
- :func:`voxel_deduplicate` and its accumulator, grown scan by scan: one point per output voxel
  of the dense cloud;
- :class:`VoxelMap`: the iVox-like local map continuous-time ICP registers against.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from nbcalib.odometry.config import DEDUP_RULES, DEFAULT_VOXEL_SIZE
from nbcalib.odometry.scans import _points_arg

__all__ = ["VoxelMap", "stratified_downsample", "voxel_deduplicate", "voxel_downsample"]


def _check_voxel(voxel_size: float, name: str = "voxel_size") -> float:
    voxel_size = float(voxel_size)
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"{name} must be a positive number, got {voxel_size!r}")
    return voxel_size


def _check_extent(points: np.ndarray, voxel_size: float) -> None:
    """Voxel keys hold coordinates in [-2^20, 2^20) voxels: refuse points beyond that."""
    from nbcalib.kernels.voxelmap import COORD_LIMIT

    if points.size and np.abs(points).max() / voxel_size >= COORD_LIMIT - 2:
        raise ValueError(
            f"points reach {np.abs(points).max():.1f} m from the origin; at a voxel of "
            f"{voxel_size} m the voxel grid covers {(COORD_LIMIT - 2) * voxel_size:.1f} m"
        )


def voxel_downsample(points: Any, voxel_size: float) -> np.ndarray:
    """Indices of the first point in each voxel ``floor(p / voxel_size)``.

    Wraps :func:`nbcalib.kernels.voxelmap._voxel_first_indices`.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Points, any frame, metres; finite.
    voxel_size : float
        Voxel edge, metres.

    Returns
    -------
    ndarray of shape (M,), int64
        Index of the first point of each occupied voxel, voxels in order of first appearance
        (so the indices are increasing).
    """
    from nbcalib.kernels.voxelmap import _voxel_first_indices

    points = _points_arg(points, "points")
    return _voxel_first_indices(points, _check_voxel(voxel_size))


def stratified_downsample(points: Any, voxel_size: float, target: int) -> np.ndarray:
    """Indices of about ``target`` points spread evenly over the occupied voxels.

    Every voxel ``floor(p / voxel_size)`` keeps ``min(count, m)`` of its points, the ``m`` chosen
    as the smallest share that reaches ``target`` points in total (all points if there are fewer);
    a voxel with more than ``m`` points keeps ranks evenly spaced in input (acquisition) order.
    When there are more voxels than ``target``, the first point of each voxel is kept and that
    list is thinned evenly to ``target``. Deterministic, unlike the reference's random grid. Wraps
    :func:`nbcalib.kernels.voxelmap._voxel_ranks`.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Points, metres; finite.
    voxel_size : float
        Voxel edge, metres.
    target : int
        Wanted number of points (the result can exceed it by less than one point per voxel).

    Returns
    -------
    ndarray of shape (M,), int64
        Increasing indices into ``points``.
    """
    from nbcalib.kernels.voxelmap import _voxel_ranks

    points = _points_arg(points, "points")
    if points.shape[0] <= target:
        return np.arange(points.shape[0])
    slot, rank, counts = _voxel_ranks(points, _check_voxel(voxel_size))
    lo, hi = 1, int(counts.max())
    while lo < hi:  # smallest share m with sum(min(counts, m)) >= target
        mid = (lo + hi) // 2
        if np.minimum(counts, mid).sum() >= target:
            hi = mid
        else:
            lo = mid + 1
    c = counts[slot]
    keep = np.flatnonzero((c <= lo) | ((rank + 1) * lo // c > rank * lo // c))
    if keep.shape[0] > target:  # more voxels than target: every voxel's first point, thinned
        keep = keep[np.linspace(0, keep.shape[0] - 1, target).round().astype(np.int64)]
    return keep


class _VoxelAccumulator:
    """One value per output voxel, grown scan by scan (wraps ``voxelmap._accumulate``)."""

    def __init__(self, voxel_size: float, rule: str, capacity: int = 1 << 16):
        if rule not in DEDUP_RULES:
            raise ValueError(f"dedup must be one of {DEDUP_RULES}, got {rule!r}")
        from nbcalib.kernels.voxelmap import RULE_LAST, RULE_MEAN, _empty_table

        self.voxel_size = _check_voxel(voxel_size)
        self.rule = RULE_MEAN if rule == "mean" else RULE_LAST
        capacity = max(int(capacity), 16)
        self.n_slots = np.zeros(1, dtype=np.int64)
        self.keys = np.empty(capacity, dtype=np.int64)
        self.values = np.empty((capacity, 5))
        self.table = _empty_table(capacity)

    def reserve(self, extra: int) -> None:
        """Make room for ``extra`` more voxels (capacity at least doubles when it grows)."""
        from nbcalib.kernels.voxelmap import _empty_table, _rehash

        n = int(self.n_slots[0])
        need = n + extra
        if need <= self.keys.shape[0]:
            return
        capacity = max(need, 2 * self.keys.shape[0])
        keys = np.empty(capacity, dtype=np.int64)
        values = np.empty((capacity, 5))
        keys[:n], values[:n] = self.keys[:n], self.values[:n]
        self.keys, self.values = keys, values
        self.table = _empty_table(capacity)
        _rehash(self.keys, n, self.table)

    def add(self, points: np.ndarray, intensity: np.ndarray) -> None:
        from nbcalib.kernels.voxelmap import _accumulate

        _check_extent(points, self.voxel_size)
        self.reserve(points.shape[0])
        _accumulate(
            self.table,
            self.keys,
            self.values,
            self.n_slots,
            points,
            intensity,
            self.voxel_size,
            self.rule,
        )

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        from nbcalib.kernels.voxelmap import RULE_MEAN

        n = int(self.n_slots[0])
        values = self.values[:n, :4]
        if self.rule == RULE_MEAN:
            values = values / self.values[:n, 4:5]
        return np.ascontiguousarray(values[:, :3]), np.ascontiguousarray(values[:, 3])


def voxel_deduplicate(
    points: Any, intensity: Any, *, voxel_size: float = DEFAULT_VOXEL_SIZE, rule: str = "mean"
) -> tuple[np.ndarray, np.ndarray]:
    """Keep one point per voxel ``floor(p / voxel_size)``.

    Wraps :func:`nbcalib.kernels.voxelmap._accumulate`.

    ``rule="mean"`` (the default) averages the points and intensities that fall into a voxel:
    the result does not depend on the order of the scans, averages out range and intensity noise
    of repeated hits (a static Livox hits the same spots many times), and stays inside the voxel.
    ``rule="last"`` keeps the last point, as the reference toolbox. Voxels are output in order of
    first appearance (the reference's hash-map order is unspecified), so the output, and the
    index map rendered from it, is the same for the same input.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Points, any frame, metres; finite.
    intensity : array_like of shape (N,)
        Their intensities.
    voxel_size : float
        Voxel edge, metres.
    rule : str
        ``"mean"`` or ``"last"``.

    Returns
    -------
    points : ndarray of shape (M, 3), float64
    intensity : ndarray of shape (M,), float64
    """
    points = _points_arg(points, "points")
    intensity = np.ascontiguousarray(intensity, dtype=np.float64).reshape(-1)
    if intensity.shape[0] != points.shape[0]:
        raise ValueError(f"{intensity.shape[0]} intensities for {points.shape[0]} points")
    accumulator = _VoxelAccumulator(voxel_size, rule, capacity=max(points.shape[0], 16))
    accumulator.add(points, intensity)
    return accumulator.result()


class VoxelMap:
    """iVox-like local map: a voxel hash with a linear container of points per voxel.

    Wraps :mod:`nbcalib.kernels.voxelmap` (``_voxelmap_insert``, ``_knn_one``, ``_rehash``);
    the semantics are in that module's docstring and the slow reference is
    :class:`nbcalib.reference.integrate.VoxelMapReference`.

    Parameters
    ----------
    voxel_size : float
        Voxel edge, metres.
    max_points_per_voxel : int
        Capacity of each voxel's container.
    min_spacing : float
        A point closer than this to a point already in its voxel is not added, metres.
    capacity : int
        Initial number of voxels (grows as needed).
    """

    def __init__(
        self,
        voxel_size: float,
        *,
        max_points_per_voxel: int = 20,
        min_spacing: float = 0.0,
        capacity: int = 4096,
    ):
        from nbcalib.kernels.voxelmap import _empty_table

        self.voxel_size = _check_voxel(voxel_size)
        if int(max_points_per_voxel) < 1:
            raise ValueError(f"max_points_per_voxel must be >= 1, got {max_points_per_voxel}")
        if not (np.isfinite(min_spacing) and min_spacing >= 0):
            raise ValueError(f"min_spacing must be >= 0, got {min_spacing}")
        self.max_points_per_voxel = int(max_points_per_voxel)
        self.min_spacing = float(min_spacing)
        capacity = max(int(capacity), 16)
        self.n_slots = np.zeros(1, dtype=np.int64)
        self.keys = np.empty(capacity, dtype=np.int64)
        self.counts = np.zeros(capacity, dtype=np.int64)
        self.store = np.zeros((capacity, self.max_points_per_voxel, 3))
        self.table = _empty_table(capacity)

    @property
    def n_voxels(self) -> int:
        """Number of occupied voxels."""
        return int(self.n_slots[0])

    def __len__(self) -> int:
        """Number of stored points."""
        return int(self.counts[: self.n_voxels].sum())

    def _resize(self, capacity: int) -> None:
        from nbcalib.kernels.voxelmap import _empty_table, _rehash

        n = self.n_voxels
        keys = np.empty(capacity, dtype=np.int64)
        counts = np.zeros(capacity, dtype=np.int64)
        store = np.zeros((capacity, self.max_points_per_voxel, 3))
        keys[:n], counts[:n], store[:n] = self.keys[:n], self.counts[:n], self.store[:n]
        self.keys, self.counts, self.store = keys, counts, store
        self.table = _empty_table(capacity)
        _rehash(self.keys, n, self.table)

    def insert(self, points: Any) -> int:
        """Add points (M, 3) (map frame, metres); returns how many were stored."""
        from nbcalib.kernels.voxelmap import _voxelmap_insert

        points = _points_arg(points, "points")
        _check_extent(points, self.voxel_size)
        need = self.n_voxels + points.shape[0]
        if need > self.keys.shape[0]:
            self._resize(max(need, 2 * self.keys.shape[0]))
        return int(
            _voxelmap_insert(
                self.table,
                self.keys,
                self.counts,
                self.store,
                self.n_slots,
                points,
                self.voxel_size,
                self.min_spacing,
            )
        )

    def remove_far(self, center: Any, max_distance: float) -> None:
        """Forget voxels whose centre is farther than ``max_distance`` from ``center`` (3,)."""
        from nbcalib.kernels.voxelmap import _unpack_all

        n = self.n_voxels
        centers = (_unpack_all(self.keys[:n]) + 0.5) * self.voxel_size
        keep = np.linalg.norm(centers - np.asarray(center, dtype=np.float64), axis=1)
        keep = keep <= max_distance
        if keep.all():
            return
        m = int(keep.sum())
        self.keys[:m] = self.keys[:n][keep]
        self.counts[:m] = self.counts[:n][keep]
        self.store[:m] = self.store[:n][keep]
        self.n_slots[0] = m
        self._resize(self.keys.shape[0])

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Stored points (M, 3) and their flat indices (M,) ``slot * P + j``, in slot order."""
        n, P = self.n_voxels, self.max_points_per_voxel
        mask = np.arange(P)[None, :] < self.counts[:n, None]
        flat = np.flatnonzero(mask.reshape(-1))
        return self.store[:n].reshape(-1, 3)[flat], flat

    def point(self, flat: Any) -> np.ndarray:
        """Stored points at flat indices (any shape) -> (..., 3)."""
        return self.store.reshape(-1, 3)[np.asarray(flat)]

    def knn(self, queries: Any, k: int, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest stored points to each query within ``max_distance``.

        Parameters
        ----------
        queries : array_like of shape (Q, 3)
            Query points, map frame, metres.
        k : int
            Neighbours per query.
        max_distance : float
            Search radius, metres; at most ``voxel_size`` (exact search).

        Returns
        -------
        indices : ndarray of shape (Q, k), int64
            Flat indices (see :meth:`points`), ascending distance, ties by index; -1 past the
            last neighbour found.
        distances_sq : ndarray of shape (Q, k), float64
            Squared distances, m^2; inf past the last neighbour.
        """
        from nbcalib.kernels.voxelmap import _voxelmap_knn

        queries = _points_arg(queries, "queries")
        if int(k) < 1:
            raise ValueError(f"k must be >= 1, got {k}")
        if not (0 < max_distance <= self.voxel_size):
            raise ValueError(
                f"max_distance must be in (0, voxel_size={self.voxel_size}], got {max_distance}"
            )
        _check_extent(queries, self.voxel_size)
        return _voxelmap_knn(
            self.table,
            self.counts,
            self.store,
            self.voxel_size,
            queries,
            int(k),
            float(max_distance),
        )
