"""How many parallel regions a numba kernel runs per call.

numba turns every NumPy array expression of a ``parallel=True`` function (``np.zeros``,
``a += b`` on arrays, ...) into a parallel loop of its own, and each one wakes the threads: about
50 us with nbcalib's passive OpenMP waiting. A kernel that should be one ``prange`` loop but
has a few such expressions around it paid 1.4-2.5 ms per call (the smooth NID, 2026-12-01).
"""

from __future__ import annotations

import numba


def parallel_regions(dispatcher, *args) -> int:
    """Parallel loops (parfors) of ``dispatcher``'s function, compiled afresh for ``args``.

    The function is recompiled with ``parallel=True`` and without the on-disk cache (a cached
    compilation has no parfor diagnostics). Array expressions nested inside a ``prange`` body
    count too, although they run serially within it: kernels zero their buffers with plain
    loops, so that 1 means exactly one ``prange`` loop and nothing else.
    """
    fresh = numba.njit(parallel=True, error_model="numpy")(dispatcher.py_func)
    fresh(*args)
    diagnostics = fresh.get_metadata(fresh.signatures[0])["parfor_diagnostics"]
    return len(diagnostics.get_parfors())
