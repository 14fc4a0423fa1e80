"""Voxel hash maps in numba: an iVox-like local map and a voxel accumulator.

Both structures key a voxel by its integer coordinates ``floor(p / voxel_size)`` (a division, as
the reference toolbox, not a multiplication by the inverse, so that kernels and references agree
bit for bit), packed into one int64 (:func:`_pack`: 21 bits per axis, so coordinates must lie in
``[-2^20, 2^20)``; the callers check the extent), and find it through an open-addressing hash
table with linear probing:

- ``table`` : int64 (H, 2), H a power of two; a bucket holds ``[packed key, slot]`` (16 bytes, so
  a probe touches one cache line), ``slot = -1`` when empty.
- ``keys`` : int64 (S,); ``keys[slot]`` is the packed key of that slot.
- ``n_slots`` : int64 (1,); slots ``0 .. n_slots[0] - 1`` are in use, numbered in order of first
  appearance, which is what makes every output order deterministic.

The callers (:class:`nbcalib.odometry.voxelmap.VoxelMap` and the accumulator there) keep
``n_slots + number of new points <= S`` and the load of the table at most
:data:`MAX_LOAD` before every insertion, so the kernels never run out of room and probe
sequences stay short.

**iVox map** (the paper's "linear iVox", Bai et al. 2022): a voxel owns a linear container of at
most ``P`` points, ``store`` float64 (S, P, 3) with ``counts`` int64 (S,). A point is appended to
its voxel unless the voxel is full or already holds a point closer than ``min_spacing``. Stored
points are identified by their *flat index* ``slot * P + j``.

**Nearest neighbours** (:func:`_knn_one`): the ``k`` stored points nearest to a query within
``max_distance``, ordered by (squared distance, flat index), searched in the 27 voxels around the
query's own voxel, its own voxel first. With ``max_distance <= voxel_size`` every point within
range lies in those 27 voxels, so the search is exact; voxels farther from the query than the
current k-th distance are skipped.

**Accumulator** (:func:`_accumulate`): one output point per voxel, either the last point that fell
into it (the reference's rule) or the running mean of its points and intensities.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels._jit import jit

EMPTY = -1

#: voxel coordinates must lie in [-COORD_LIMIT, COORD_LIMIT) to be packed
COORD_LIMIT = 1 << 20
_BITS = 21
_MASK21 = (1 << _BITS) - 1

#: largest fill of a hash table (slots / buckets) the callers allow
MAX_LOAD = 0.5

# odd 63-bit multiplier (splitmix64); int64 products wrap, which is what we want
_MIX = 0x1F3779B97F4A7C15

# a voxel whose box is farther than the search bound (plus this relative margin) is skipped; the
# margin absorbs the rounding of floor(p / voxel) at voxel faces
_BOX_MARGIN = 1e-9

#: accumulator rules
RULE_LAST = 0
RULE_MEAN = 1


@jit
def _voxel_coord(x, voxel_size):
    return np.int64(math.floor(x / voxel_size))


@jit
def _pack(ix, iy, iz):
    """One int64 for voxel (ix, iy, iz), each in [-2^20, 2^20)."""
    return ((ix + COORD_LIMIT) << (2 * _BITS)) | ((iy + COORD_LIMIT) << _BITS) | (iz + COORD_LIMIT)


@jit
def _unpack(key):
    """Voxel coordinates (ix, iy, iz) of a packed key."""
    ix = ((key >> (2 * _BITS)) & _MASK21) - COORD_LIMIT
    iy = ((key >> _BITS) & _MASK21) - COORD_LIMIT
    iz = (key & _MASK21) - COORD_LIMIT
    return ix, iy, iz


@jit
def _point_key(x, y, z, voxel_size):
    return _pack(
        _voxel_coord(x, voxel_size), _voxel_coord(y, voxel_size), _voxel_coord(z, voxel_size)
    )


@jit
def _bucket(key, mask):
    h = key * _MIX
    h ^= h >> 29
    return h & mask


@jit
def _lookup(table, key):
    """Slot of ``key``, or ``-1 - bucket`` with the empty bucket where it would go."""
    mask = table.shape[0] - 1
    b = _bucket(key, mask)
    while True:
        s = table[b, 1]
        if s < 0:
            return -1 - b
        if table[b, 0] == key:
            return s
        b = (b + 1) & mask


@jit
def _find_or_add(table, keys, n_slots, key):
    """Slot of ``key``, added as the next slot if new; returns (slot, added)."""
    s = _lookup(table, key)
    if s >= 0:
        return s, False
    b = -1 - s
    s_new = n_slots[0]
    n_slots[0] = s_new + 1
    table[b, 0] = key
    table[b, 1] = s_new
    keys[s_new] = key
    return s_new, True


@jit
def _empty_table(n):
    """A table for up to ``n`` slots (load at most :data:`MAX_LOAD`), all buckets empty."""
    size = 16
    while size * MAX_LOAD < n:
        size *= 2
    table = np.empty((size, 2), dtype=np.int64)
    table[:, 1] = EMPTY
    return table


@jit
def _rehash(keys, n, table):
    """Fill an empty ``table`` with slots ``0 .. n - 1`` of ``keys``."""
    for s in range(n):
        b = -1 - _lookup(table, keys[s])
        table[b, 0] = keys[s]
        table[b, 1] = s


@jit
def _unpack_all(keys):
    """Voxel coordinates (S, 3) int64 of packed keys (S,)."""
    out = np.empty((keys.shape[0], 3), dtype=np.int64)
    for s in range(keys.shape[0]):
        out[s, 0], out[s, 1], out[s, 2] = _unpack(keys[s])
    return out


# ---------------------------------------------------------------------------------------------
# iVox map


@jit
def _voxelmap_insert(table, keys, counts, store, n_slots, points, voxel_size, min_spacing):
    """Append ``points`` (M, 3) to their voxels (module docstring); returns how many were kept."""
    capacity = store.shape[1]
    min_d2 = min_spacing * min_spacing
    kept = 0
    for i in range(points.shape[0]):
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        s, added = _find_or_add(table, keys, n_slots, _point_key(x, y, z, voxel_size))
        if added:
            counts[s] = 0
        c = counts[s]
        if c >= capacity:
            continue
        far = True
        for j in range(c):
            dx = store[s, j, 0] - x
            dy = store[s, j, 1] - y
            dz = store[s, j, 2] - z
            if dx * dx + dy * dy + dz * dz < min_d2:
                far = False
                break
        if far:
            store[s, c, 0] = x
            store[s, c, 1] = y
            store[s, c, 2] = z
            counts[s] = c + 1
            kept += 1
    return kept


@jit
def _box_d2(q, lo, voxel_size):
    """Squared distance from ``q`` to the interval [lo, lo + voxel_size] (one axis)."""
    if q < lo:
        return (lo - q) * (lo - q)
    hi = lo + voxel_size
    if q > hi:
        return (q - hi) * (q - hi)
    return 0.0


def _neighbour_offsets():
    """The 27 voxel offsets, the voxel itself first, then faces, edges and corners."""
    offsets = [(x, y, z) for x in (-1, 0, 1) for y in (-1, 0, 1) for z in (-1, 0, 1)]
    offsets.sort(key=lambda o: abs(o[0]) + abs(o[1]) + abs(o[2]))
    return np.array(offsets, dtype=np.int64)


#: search order of :func:`_knn_one` (near voxels first, so the k-th distance shrinks early)
NEIGHBOUR_OFFSETS = _neighbour_offsets()


@jit
def _knn_one(table, counts, store, voxel_size, qx, qy, qz, max_d2, out_idx, out_d2):
    """The ``k = out_idx.size`` nearest stored points to (qx, qy, qz) within ``sqrt(max_d2)``.

    Writes flat indices and squared distances in ascending (d2, flat index) order into
    ``out_idx`` / ``out_d2``, and returns how many were found; the rest is -1 / inf.
    """
    k = out_idx.shape[0]
    capacity = store.shape[1]
    for j in range(k):
        out_idx[j] = -1
        out_d2[j] = np.inf
    n = 0
    cx = _voxel_coord(qx, voxel_size)
    cy = _voxel_coord(qy, voxel_size)
    cz = _voxel_coord(qz, voxel_size)
    for o in range(NEIGHBOUR_OFFSETS.shape[0]):
        ox = NEIGHBOUR_OFFSETS[o, 0]
        oy = NEIGHBOUR_OFFSETS[o, 1]
        oz = NEIGHBOUR_OFFSETS[o, 2]
        box = (
            _box_d2(qx, (cx + ox) * voxel_size, voxel_size)
            + _box_d2(qy, (cy + oy) * voxel_size, voxel_size)
            + _box_d2(qz, (cz + oz) * voxel_size, voxel_size)
        )
        bound = max_d2 if n < k else out_d2[k - 1]
        if box > bound * (1.0 + _BOX_MARGIN):
            continue
        s = _lookup(table, _pack(cx + ox, cy + oy, cz + oz))
        if s < 0:
            continue
        for j in range(counts[s]):
            dx = store[s, j, 0] - qx
            dy = store[s, j, 1] - qy
            dz = store[s, j, 2] - qz
            d2 = dx * dx + dy * dy + dz * dz
            if d2 > max_d2:
                continue
            flat = s * capacity + j
            if n == k and (d2 > out_d2[k - 1] or (d2 == out_d2[k - 1] and flat > out_idx[k - 1])):
                continue
            # insertion sort by (d2, flat)
            m = n if n < k else k - 1
            while m > 0 and (out_d2[m - 1] > d2 or (out_d2[m - 1] == d2 and out_idx[m - 1] > flat)):
                out_d2[m] = out_d2[m - 1]
                out_idx[m] = out_idx[m - 1]
                m -= 1
            out_d2[m] = d2
            out_idx[m] = flat
            if n < k:
                n += 1
    return n


@jit
def _voxelmap_knn(table, counts, store, voxel_size, queries, k, max_distance):
    """:func:`_knn_one` for each row of ``queries`` (Q, 3); returns (Q, k) indices and d2."""
    nq = queries.shape[0]
    idx = np.empty((nq, k), dtype=np.int64)
    d2 = np.empty((nq, k))
    max_d2 = max_distance * max_distance
    for i in range(nq):
        _knn_one(
            table,
            counts,
            store,
            voxel_size,
            queries[i, 0],
            queries[i, 1],
            queries[i, 2],
            max_d2,
            idx[i],
            d2[i],
        )
    return idx, d2


# ---------------------------------------------------------------------------------------------
# Voxel grid downsampling and accumulation


@jit
def _voxel_ranks(points, voxel_size):
    """Voxel slot, rank within the voxel and points per voxel.

    Returns the slot of each point (slots in order of first appearance), the point's rank among
    the points of its voxel (in input order) and the number of points per slot.
    """
    n = points.shape[0]
    table = _empty_table(n)
    keys = np.empty(n, dtype=np.int64)
    n_slots = np.zeros(1, dtype=np.int64)
    slot = np.empty(n, dtype=np.int64)
    rank = np.empty(n, dtype=np.int64)
    counts = np.zeros(n, dtype=np.int64)
    for i in range(n):
        s, _ = _find_or_add(
            table, keys, n_slots, _point_key(points[i, 0], points[i, 1], points[i, 2], voxel_size)
        )
        slot[i] = s
        rank[i] = counts[s]
        counts[s] += 1
    return slot, rank, counts[: n_slots[0]].copy()


@jit
def _voxel_first_indices(points, voxel_size):
    """Index of the first point of each voxel, voxels in order of first appearance."""
    slot, rank, counts = _voxel_ranks(points, voxel_size)
    first = np.empty(counts.shape[0], dtype=np.int64)
    for i in range(points.shape[0]):
        if rank[i] == 0:
            first[slot[i]] = i
    return first


@jit
def _accumulate(table, keys, values, n_slots, points, intensity, voxel_size, rule):
    """Fold ``points`` (M, 3) and ``intensity`` (M,) into one value per voxel.

    ``values`` float64 (S, 5) holds per slot x, y, z, intensity and the number of points: the
    last point of the voxel (``rule == RULE_LAST``) or the running sums (``RULE_MEAN``; the
    caller divides by the count).
    """
    for i in range(points.shape[0]):
        s, added = _find_or_add(
            table, keys, n_slots, _point_key(points[i, 0], points[i, 1], points[i, 2], voxel_size)
        )
        if added:
            values[s, 0] = 0.0
            values[s, 1] = 0.0
            values[s, 2] = 0.0
            values[s, 3] = 0.0
            values[s, 4] = 0.0
        values[s, 4] += 1.0
        if rule == RULE_MEAN:
            values[s, 0] += points[i, 0]
            values[s, 1] += points[i, 1]
            values[s, 2] += points[i, 2]
            values[s, 3] += intensity[i]
        else:
            values[s, 0] = points[i, 0]
            values[s, 1] = points[i, 1]
            values[s, 2] = points[i, 2]
            values[s, 3] = intensity[i]
