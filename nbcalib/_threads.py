"""Independent per-pair work on every core: :func:`thread_map`.

Preprocessing reads, integrates, renders and writes each pair on its own; most of that time is
spent in numba kernels (compiled ``nogil``), NumPy and file I/O, which release the GIL, so
threads share the cores without copying a dense cloud into another process. The results are
the same as one pair after another (tests/test_preprocess.py); only the order of log lines may
differ. Where numba's threading layer cannot run parallel kernels from two threads at once
(``workqueue``), the items run one after another.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

__all__ = ["WORKERS", "thread_map"]

T = TypeVar("T")
R = TypeVar("R")

#: Threads of :func:`thread_map` (None: one per core). Set to 1 for one item after another.
WORKERS: int | None = None


def thread_map(func: Callable[[T], R], items: Iterable[T], workers: int | None = None) -> list[R]:
    """``[func(x) for x in items]`` on up to ``workers`` threads (default :data:`WORKERS`).

    The results keep the items' order; an exception is raised as the plain loop would raise
    the first one in that order (the other items' work may have run).
    """
    items = list(items)
    n = workers or WORKERS or os.cpu_count() or 1
    n = min(n, len(items))
    if n <= 1 or not _parallel_kernels_thread_safe():
        return [func(x) for x in items]
    with ThreadPoolExecutor(max_workers=n, thread_name_prefix="nbcalib") as pool:
        return list(pool.map(func, items))


@functools.cache  # the layer is fixed once numba is configured: asked once, not per call
def _parallel_kernels_thread_safe() -> bool:
    """Whether numba's threading layer lets two threads run parallel kernels at once.

    The OpenMP and TBB layers do; ``workqueue`` (numba's fallback when neither is installed,
    as on some macOS builds) aborts the process on concurrent use, so there the work runs one
    item after another.
    """
    import numba

    layer = str(numba.config.THREADING_LAYER).lower()
    if layer == "workqueue":
        return False
    for name in ("tbbpool", "omppool") if layer in ("default", "safe", "threadsafe") else ():
        try:
            __import__(f"numba.np.ufunc.{name}")
            return True
        except ImportError:
            continue
    return layer in ("omp", "tbb")
