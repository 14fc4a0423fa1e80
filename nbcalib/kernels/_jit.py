"""JIT options for every numba kernel in nbcalib, kept in one place.

Kernels are decorated with :data:`jit` (serial) or :data:`jit_parallel`; nothing else in the
package passes options to numba. ``cache=True`` keeps compiled machine code between processes
(numba writes it beside the sources or to ``NUMBA_CACHE_DIR``).

numba's all-flags fast-math mode is never used: its ``nnan``/``ninf`` flags let LLVM assume that
no value is NaN or inf, and the z-buffers (inf-initialised) and validity checks (NaN for invalid
points) depend on exactly those values. :data:`FASTMATH_SAFE` lists the flags that keep IEEE
semantics for inf and NaN; a kernel opts into them explicitly where a benchmark shows a gain.
"""

from __future__ import annotations

import os
import types

# numba's default threading layer on Linux is OpenMP (libgomp), whose idle threads spin for a
# while before sleeping. When the cores are busy with anything else that spinning starves the
# threads doing work: a parallel NID evaluation of 120 k points took 670 ms of wall time next to
# a running test suite on 2 cores, 71 ms with passive waiting and 100 ms serial (benchmarks/
# bench_nid.py; docs/BENCHMARKS.md). libgomp reads the policy when numba first loads it, so it
# is set here, before any parallel kernel runs; a value the user exported wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba

#: LLVM fast-math flags that keep inf/NaN semantics (no ``nnan``, no ``ninf``).
FASTMATH_SAFE = frozenset({"nsz", "arcp", "contract", "afn", "reassoc"})

#: Options of every serial kernel.
JIT_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}

#: Options of every parallel kernel (only where a benchmark shows a gain).
JIT_PARALLEL_OPTIONS = {**JIT_OPTIONS, "parallel": True}

#: Options of small per-point helpers that hot loops call (camera projections): numba inlines
#: them into the caller at IR level, so LLVM sees one flat loop. Measured on the plumb_bob
#: projection loop: 22 M points/s through an ordinary call, 90-115 M/s inlined; inlining the big
#: Jacobian helpers instead cost ~18 s of compilation per caller, so only value helpers use it.
JIT_INLINE_OPTIONS = {**JIT_OPTIONS, "inline": "always"}


def _njit(options: dict, f):
    """``numba.njit(**options)(f)``, without the on-disk cache where none can be written.

    numba refuses ``cache=True`` ("cannot cache function") when neither the package's folder nor
    the user's cache folder is writable: a read-only install run by a user without a home. The
    kernels then compile in every process instead of failing to import.
    """
    try:
        return numba.njit(**options)(f)
    except RuntimeError as exc:
        if not options.get("cache") or "cannot cache" not in str(exc):
            raise
        return numba.njit(**{**options, "cache": False})(f)


def jit(func=None, *, fastmath=False):
    """Compile ``func`` as a serial nopython kernel with the project's options."""

    def wrap(f):
        return _njit({**JIT_OPTIONS, "fastmath": set(fastmath) if fastmath else False}, f)

    return wrap if func is None else wrap(func)


def jit_inline(func=None, *, fastmath=False):
    """Compile ``func`` as a small helper that numba inlines into every kernel calling it."""

    def wrap(f):
        return _njit({**JIT_INLINE_OPTIONS, "fastmath": set(fastmath) if fastmath else False}, f)

    return wrap if func is None else wrap(func)


def _renamed(func, suffix: str):
    """A copy of ``func`` whose name (and so whose numba cache files) end in ``suffix``.

    numba names its on-disk cache files after the function's qualified name and keys entries by
    signature and bytecode, not by the ``parallel`` flag: a serial and a parallel dispatcher of
    one Python function would share one cache entry, and a later process would load whichever
    compiled first for both.
    """
    name = func.__name__ + suffix
    names = {"co_name": name}
    if hasattr(func.__code__, "co_qualname"):  # Python >= 3.11
        names["co_qualname"] = func.__code__.co_qualname + suffix
    code = func.__code__.replace(**names)
    copy = types.FunctionType(code, func.__globals__, name, func.__defaults__, func.__closure__)
    copy.__qualname__ = func.__qualname__ + suffix
    copy.__kwdefaults__ = func.__kwdefaults__
    copy.__module__ = func.__module__
    copy.__doc__ = func.__doc__
    return copy


def jit_parallel(func=None, *, fastmath=False):
    """Compile ``func`` as a parallel (``prange``) nopython kernel with the project's options.

    The kernel is compiled from a renamed copy of ``func`` (suffix ``_parallel``), so that it has
    numba cache files of its own even when ``func`` is also compiled serially with :func:`jit`.
    """

    def wrap(f):
        options = dict(JIT_PARALLEL_OPTIONS, fastmath=set(fastmath) if fastmath else False)
        return _njit(options, _renamed(f, "_parallel"))

    return wrap if func is None else wrap(func)
