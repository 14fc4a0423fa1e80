"""Compile the later stages' numba kernels ahead, in a background process, on a first run.

numba compiles a kernel the first time it is called and caches the machine code on disk
(``cache=True``, :mod:`nbcalib.kernels._jit`). On a fresh install that first call costs
seconds per kernel, about 40 s for a whole job on two cores, most of it in fine registration
and the report, and all of it on the job's critical path. While the first stages of a job run
(reading, simulating, preprocessing, matching: mostly one core, or ONNX Runtime's threads),
:func:`start` lets a second process, at low priority, run a tiny in-memory calibration through
the same pipeline functions: it compiles the kernels of preprocessing, rendering, matching's
views and RANSAC, fine registration and the report, and numba writes them to the cache, where
the job finds them when it gets there. With a warm cache (any later run) nothing is started.

``nbcalib demo`` and ``nbcalib run`` call :func:`start`; ``NBCALIB_NO_WARMUP=1`` turns it off.
``python -m nbcalib.warmup_job`` runs the tiny job in the foreground (the same one).

This module only knows the cache and the process, so that the stages can ask it
(:func:`running`) without importing the pipeline; the tiny job, which runs the pipeline, is
:mod:`nbcalib.warmup_job`, above it.
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

__all__ = ["cache_is_warm", "compiling_note", "running", "start"]

log = logging.getLogger("nbcalib.warmup")

#: A kernel of fine registration whose cached index marks a warm cache.
_MARKER = ("nid", "_joint_hist_smooth_impl")


def cache_is_warm() -> bool:
    """True when numba's cache holds fine registration's NID kernel.

    The cache is beside the kernels, or under ``NUMBA_CACHE_DIR`` when that is set.
    """
    module, kernel = _MARKER
    pattern = f"{module}.{kernel}-*.nbi"
    custom = os.environ.get("NUMBA_CACHE_DIR")
    if custom:
        return any(Path(custom).rglob(pattern))
    return any((Path(__file__).parent / "kernels" / "__pycache__").glob(pattern))


#: What a first run says before its kernels compile. Measured on two cores (BENCHMARKS.md 7
#: and 9): the demo about 20 s more than warm (with the background warm-up), a notebook 12-53 s.
COMPILING_NOTE = (
    "first run on this machine: numba compiles nbcalib's kernels as they are first used, "
    "up to about a minute on two cores, once (later runs load them from the cache)"
)


def compiling_note() -> bool:
    """Say (an INFO line of ``nbcalib.warmup``) that kernels will compile, when the cache is cold.

    Returns whether it was said.
    """
    if cache_is_warm():
        return False
    log.info(COMPILING_NOTE)
    return True


def _cache_writable() -> bool:
    """True when numba can keep what the warm-up compiles (else it compiles for nothing)."""
    custom = os.environ.get("NUMBA_CACHE_DIR")
    folder = Path(custom) if custom else Path(__file__).parent / "kernels"
    return os.access(folder, os.W_OK)


#: The warm-up process this process started (None: none was).
_process: subprocess.Popen | None = None


def running() -> bool:
    """True while the warm-up process this process started is still compiling.

    Matching asks (:func:`nbcalib.matching.match.match_images`): ONNX Runtime then leaves the
    warm-up a core instead of racing it for both (docs/BENCHMARKS.md 7).
    """
    return _process is not None and _process.poll() is None


def start() -> subprocess.Popen | None:
    """Start :func:`~nbcalib.warmup_job.tiny_job` in a low-priority background process, if needed.

    Returns the process (None when the cache is warm or cannot be written,
    ``NBCALIB_NO_WARMUP`` is set, or it cannot be started); :func:`running` says whether it
    still runs. It is never waited for: the job it helps does not depend on it.
    """
    global _process
    if os.environ.get("NBCALIB_NO_WARMUP") or cache_is_warm() or not _cache_writable():
        return None

    def lower_priority():  # runs in the child before exec
        os.nice(10)

    try:
        _process = subprocess.Popen(
            [sys.executable, "-m", "nbcalib.warmup_job"],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
            preexec_fn=lower_priority,
            env={**os.environ, "NBCALIB_NO_WARMUP": "1"},
        )
        return _process
    except OSError as exc:  # no fork, no interpreter: the job just compiles as it goes
        log.debug("no warm-up process: %s", exc)
        return None
