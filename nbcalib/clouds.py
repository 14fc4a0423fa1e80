"""A pair's dense cloud: held in memory, or read again from the work directory when needed.

A long recording's dense clouds do not fit in memory together: fifteen Livox pairs hold 33 M
points, 1.1 GB as float64, and fine registration and the report compute as much again from
them (visible sets, sample keys, KD-trees). So a pair does not own its cloud's arrays; it owns
a :class:`Cloud`, which either

- **holds** them (a job made in memory, the API given arrays, a test), or
- **reads** them from the work directory's PLY each time they are needed (a job with a work
  directory, once a pair is written), its size known from the file's header alone.

Whatever is computed from a cloud and can be computed again (the file's float32 values, half
the float64 arrays' size, the KD-tree, the sample keys, the visible sets) goes through
:meth:`Cloud.memo`, which keeps it in the job's :class:`MemoryBudget` while the budget has room
and otherwise hands it over without keeping it. Every such product is a deterministic function
of the cloud, so what is kept changes the time a job takes, never a number it computes. A held
cloud keeps its products without limit, as before the budget existed. The orientation classes
of the points (:meth:`nbcalib.registration.pair.RegistrationPair.orientation_classes`) stay
with the cloud: one byte per point, computed once.

A stage that uses a read cloud several times in a row pins it (``with cloud.held():``), so that
it is read once for that stretch and released after, and takes the rows it needs
(:meth:`Cloud.rows`): a cost's subset widened to float64, not the whole cloud.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from contextlib import contextmanager
from pathlib import Path

import numpy as np

__all__ = ["Cloud", "MemoryBudget", "nbytes"]

#: How much of the budget each kind of product may fill (:meth:`MemoryBudget.get`), by what it
#: costs to make again per byte (a Livox pair, this Xeon): a visible set (a z-buffer, 0.1 s for
#: 15 MB) and a KD-tree (seconds) may fill it all; the sample keys (a draw, 15 ms for 8.5 MB)
#: half; the file's values (a read, 15 ms for 34 MB) a quarter. The cheapest leave room for
#: the dearest: the report asks each pair's visible set at the result four times.
SHARES = {"file": 0.25, "keys": 0.5}


def nbytes(value) -> int:
    """Bytes of an array, or of a tuple or list of arrays (other items count 0)."""
    if isinstance(value, np.ndarray):
        return int(value.nbytes)
    if isinstance(value, (tuple, list)):
        return sum(nbytes(v) for v in value)
    return int(getattr(value, "nbytes_estimate", 0))


class MemoryBudget:
    """What a job keeps of the products it can compute again, up to ``limit`` bytes.

    A product that does not fit is handed over without being kept: nothing already kept is
    pushed out for it. A job visits its pairs in turn at every step, so pushing out the oldest
    would push out each pair's products just before they are asked for again; keeping the first
    that fit serves those pairs from memory and reads the others, at a steady cost. Owners drop
    what they no longer need (:meth:`drop`), which makes room again.

    Parameters
    ----------
    limit : int or None
        Bytes (None: no limit, everything is kept).
    """

    def __init__(self, limit: int | None):
        if limit is not None and limit < 0:
            raise ValueError(f"a memory budget is at least 0 bytes, got {limit}")
        self.limit = limit
        self.used = 0
        self._items: dict[Hashable, tuple[object, int]] = {}
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        limit = "none" if self.limit is None else f"{self.limit / 2**20:.0f} MB"
        return f"MemoryBudget({self.used / 2**20:.0f} MB of {limit}, {len(self._items)} items)"

    def get(self, key: Hashable, make: Callable[[], object], *, share: float = 1.0) -> object:
        """The product kept under ``key``, or ``make()`` (kept if it fits).

        ``share``: kept only while the budget is used to at most this fraction of its limit,
        so that the bulkiest products, the cheapest to make again, leave room for the others.
        """
        with self._lock:
            found = self._items.get(key)
        if found is not None:
            return found[0]
        value = make()
        size = nbytes(value)
        with self._lock:
            room = None if self.limit is None else share * self.limit
            if key not in self._items and (room is None or self.used + size <= room):
                self._items[key] = (value, size)
                self.used += size
        return value

    def drop(self, key: Hashable) -> None:
        """Forget the product under ``key`` (nothing if none)."""
        with self._lock:
            found = self._items.pop(key, None)
            if found is not None:
                self.used -= found[1]


def _read_ply_cloud(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Points (N, 3) and intensities (N,) of a work directory's PLY, in the file's dtype.

    The work directory stores float32: kept so, a cloud takes half the memory of the float64
    arrays the stages use (:meth:`Cloud.arrays` converts, exactly). Stored as nbcalib writes it
    (x, y, z, intensity, float32), both are views of the block read from the file: no copy.
    """
    from nbcalib.errors import InputError
    from nbcalib.io.ply import read_ply_fields, read_ply_xyzi

    block = read_ply_xyzi(path)
    if block is not None:
        return block[:, :3], block[:, 3]
    fields = read_ply_fields(path)
    missing = [k for k in ("x", "y", "z", "intensity") if k not in fields]
    if missing:
        raise InputError(f"the cloud lacks the vertex properties {missing}", path)
    return np.column_stack([fields[k] for k in "xyz"]), np.asarray(fields["intensity"])


class Cloud:
    """A dense cloud and what is computed from it (module docstring).

    Parameters
    ----------
    points : ndarray of shape (N, 3), optional
        The points, held (give ``intensities`` with them).
    intensities : ndarray of shape (N,), optional
    path : path, optional
        Instead of arrays: a PLY with ``x, y, z, intensity``, read when the arrays are asked
        for (float64, the file's float32 values).
    size : int, optional
        With ``path``: its number of points (from its header).
    budget : MemoryBudget, optional
        With ``path``: where the products are kept (default: nothing is kept).
    classes : ndarray of shape (N,), int8, optional
        Orientation classes already known (-1: not yet).
    """

    def __init__(
        self,
        points=None,
        intensities=None,
        *,
        path=None,
        size: int | None = None,
        budget: MemoryBudget | None = None,
        classes=None,
    ):
        if (points is None) == (path is None):
            raise ValueError("a cloud is given either its arrays or the path of its file")
        if points is not None:
            if intensities is None:
                raise ValueError("a cloud's points need their intensities")
            self._arrays: tuple | None = (points, intensities)
            self.path = None
            self.size = int(np.shape(points)[0])
            self.budget = MemoryBudget(None)
        else:
            if size is None:
                raise ValueError("a cloud read from a file needs its size")
            self._arrays = None
            self.path = Path(path)
            self.size = int(size)
            self.budget = budget if budget is not None else MemoryBudget(0)
        self.classes = None if classes is None else np.asarray(classes, dtype=np.int8)
        #: The keys of the visible sets kept, the last asked last (a pair keeps two).
        self.visible_keys: list = []
        self._pins = 0
        self._pinned: tuple | None = None
        self._lock = threading.RLock()

    @classmethod
    def given(cls, cloud=None, points=None, intensities=None, classes=None) -> Cloud:
        """The cloud a pair is made with: ``cloud``, or new arrays held.

        Arrays make a new cloud, the missing one taken from ``cloud`` (as
        ``dataclasses.replace(pair, points_lidar=...)`` passes the old cloud along).
        """
        if points is None and intensities is None:
            if cloud is None:
                raise ValueError("a pair needs its points and intensities, or a cloud")
            if classes is not None:
                cloud.classes = np.asarray(classes, dtype=np.int8)
            return cloud
        if cloud is not None:
            points = cloud.points if points is None else points
            intensities = cloud.intensities if intensities is None else intensities
        if points is None or intensities is None:
            raise ValueError("a pair needs its points and intensities, or a cloud")
        return cls(points, intensities, classes=classes)

    def __repr__(self) -> str:
        where = "held" if self.path is None else f"read from {self.path.name}"
        return f"Cloud({self.size} points, {where})"

    def __len__(self) -> int:
        return self.size

    @property
    def held_in_memory(self) -> bool:
        """Whether the arrays are held (not read from a file)."""
        return self.path is None

    def stored(self) -> tuple[np.ndarray, np.ndarray]:
        """``(points, intensities)`` as stored: float32 for a cloud read from its file.

        Held, pinned, kept in the budget, or read now; to be read only (they may be shared).
        """
        if self._arrays is not None:
            return self._arrays
        with self._lock:
            if self._pinned is not None:
                return self._pinned
        return self.memo("file", lambda: _read_ply_cloud(self.path))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """``(points, intensities)``, float64 for a cloud read from its file (exact)."""
        return self.points, self.intensities

    def rows(self, index) -> tuple[np.ndarray, np.ndarray]:
        """``(points[index], intensities[index])``, float64 for a cloud read from its file.

        The rows are taken before the file's float32 values are widened (exactly): a cost's
        few hundred thousand points, not the whole cloud.
        """
        points, intensities = self.stored()
        return self._wide(points[index]), self._wide(np.asarray(intensities)[index])

    @property
    def points(self) -> np.ndarray:
        """The points (N, 3), LiDAR frame, metres (float64 for a cloud read from its file)."""
        return self._wide(self.stored()[0])

    @property
    def intensities(self) -> np.ndarray:
        """The intensities (N,), in [0, 1] (float64 for a cloud read from its file)."""
        return self._wide(self.stored()[1])

    def _wide(self, values: np.ndarray) -> np.ndarray:
        """Held values as given; the file's float32 widened to float64 (exact)."""
        return values if self._arrays is not None else values.astype(np.float64)

    @contextmanager
    def held(self):
        """Keep the cloud's values in memory while the block runs (read once for it).

        What is pinned is the file's own values (float32): :meth:`rows` takes from them and
        :meth:`arrays` widens them when the whole cloud is asked for.
        """
        with self._lock:
            if self._pins == 0 and self._arrays is None:
                self._pinned = self.stored()
            self._pins += 1
        try:
            yield
        finally:
            with self._lock:
                self._pins -= 1
                if self._pins == 0:
                    self._pinned = None

    def memo(self, key: Hashable, make: Callable[[], object]) -> object:
        """A product of this cloud: kept under ``key`` in the budget, or ``make()``.

        ``key`` is a name, or a tuple whose first item is one: its kind, whose share of the
        budget :data:`SHARES` gives (1 when not listed).
        """
        kind = key[0] if isinstance(key, tuple) else key
        return self.budget.get((id(self), key), make, share=SHARES.get(kind, 1.0))

    def forget(self, key: Hashable) -> None:
        """Drop a product of this cloud from the budget."""
        self.budget.drop((id(self), key))

    def __del__(self):  # a cloud's products go with it (an id is reused once freed)
        budget = getattr(self, "budget", None)
        if budget is not None and budget.limit != 0:
            with budget._lock:
                mine = [k for k in budget._items if isinstance(k, tuple) and k[0] == id(self)]
            for k in mine:
                budget.drop(k)
