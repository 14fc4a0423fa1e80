"""Freed arrays back to the operating system (glibc): :func:`return_freed_arrays`.

glibc gives an allocation above its *mmap threshold* a mapping of its own, which goes back to the
system when the array is freed. But each time such a block is freed it raises the threshold to
that block's size (up to 32 MB), and from then on arrays of that size come from the heap, whose
freed pages the process keeps. A job that reads, projects and drops a dense cloud per pair and
per step frees arrays of every size from 1 to 70 MB, so its heap only grows: a fifteen-pair
Livox job peaked 0.45 GB higher for it (docs/BENCHMARKS.md, section 15). Setting the threshold
once fixes it, so arrays of :data:`THRESHOLD` bytes and more are always mapped on their own.

It has a price: an array mapped on its own is zeroed page by page when first written, where one
from the heap reuses pages already there. A single Livox pair's job took 8 % longer with it
(44.7 s against 41.3, medians of three runs side by side), while fifteen pairs took as long and
peaked 0.3 GB lower. So the pipeline sets it for jobs of :data:`MANY_PAIRS` pairs or more
(`Calibrator._memory`, once it knows its pairs), the CLI and the API alike. Where
the C library is not glibc (macOS, musl) it does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["MANY_PAIRS", "THRESHOLD", "return_freed_arrays"]

#: Arrays of this many bytes and more get a mapping of their own (4 MB: 1 MB cost 10-20 % more
#: time in page faults, for 7 MB less at the peak).
THRESHOLD = 4 << 20

#: Jobs of this many pairs or more return their freed arrays.
MANY_PAIRS = 3

#: glibc's ``mallopt`` parameter for the mmap threshold (malloc.h).
_M_MMAP_THRESHOLD = -3


def return_freed_arrays() -> bool:
    """Fix glibc's mmap threshold at :data:`THRESHOLD`; True if it was set.

    Not when the environment sets glibc's own ``MALLOC_MMAP_THRESHOLD_`` (which glibc then
    applies itself): a user's choice is kept.
    """
    import os

    if "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # no glibc
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return mallopt(_M_MMAP_THRESHOLD, THRESHOLD) == 1
