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
``python -m nbcalib.warmup`` runs the tiny job in the foreground (the same one).
"""

from __future__ import annotations

import logging
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

__all__ = ["cache_is_warm", "compiling_note", "running", "start", "tiny_job"]

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
    """Start :func:`tiny_job` in a low-priority background process, unless not needed.

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
            [sys.executable, "-m", "nbcalib.warmup"],
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


def _scene(rng: np.random.Generator, camera):
    """A textured corner (back wall, floor, side wall) seen by a pinhole ``camera``.

    Points are in the camera frame; their intensity is the texture at their position, the
    image the texture at each pixel's first hit.
    """

    def texture(p):
        return 0.5 + 0.25 * np.sin(3.1 * p[..., 0] + 1.3 * p[..., 2]) * np.cos(2.7 * p[..., 1])

    planes = [  # (normal axis, offset): z = 6 back wall, y = 1.5 floor, x = -3 side wall
        (2, 6.0),
        (1, 1.5),
        (0, -3.0),
    ]
    h, w = camera.height, camera.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    # a pinhole's rays by its intrinsics: the job compiles the unprojection kernels itself
    # at once (synth, reading), so the warm-up does not race it for them
    fx, fy, cx, cy = camera.intrinsics[:4]
    rays = np.column_stack([(u.ravel() - cx) / fx, (v.ravel() - cy) / fy, np.ones(u.size)])
    depth = np.full(len(rays), np.inf)
    for axis, offset in planes:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = offset / rays[:, axis]
        depth = np.where((s > 0.5) & (s < depth), s, depth)
    hit = rays * np.where(np.isfinite(depth), depth, 0.0)[:, None]
    image = np.where(np.isfinite(depth), texture(hit), 0.0).reshape(h, w)
    points = []
    for axis, offset in planes:
        p = rng.uniform((-3.0, -2.0, 1.0), (3.0, 1.5, 6.0), (15000, 3))
        p[:, axis] = offset
        points.append(p)
    points = np.concatenate(points)
    return (255 * image).astype(np.uint8), points, texture(points)


def tiny_job() -> None:
    """Calibrate a small synthetic scene in memory, through the stages a job runs.

    In the order a job needs its kernels: preprocessing and rendering, the initial guess's
    RANSAC, matching's views, then fine registration and the report.
    """
    from nbcalib.api import ArrayInputs
    from nbcalib.camera import example_camera
    from nbcalib.config import CalibrationConfig, set_values
    from nbcalib.initial_guess.estimate import estimate_initial_guess
    from nbcalib.matching.multiview import match_views
    from nbcalib.pipeline import Calibrator
    from nbcalib.products import Start
    from nbcalib.transforms import se3_exp

    rng = np.random.default_rng(0)
    camera = example_camera("pinhole", 320, 240)
    image, points_camera, intensities = _scene(rng, camera)
    # a LiDAR with REP 103 axes (x forward) at the camera
    T_camera_lidar = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
    points = points_camera @ T_camera_lidar[:3, :3]
    inputs = ArrayInputs([points], [intensities], [image], camera)
    calibrator = Calibrator(set_values(CalibrationConfig(), {"refine.max_outer": 2}))
    calibrator.run(inputs, until="preprocess")
    uv, valid = camera.project(points_camera[:400])
    estimate_initial_guess(camera, uv[valid], points[:400][valid], seed=0)
    match_views(camera, image, points, intensities, matcher="sift", views=2)
    near = se3_exp(np.array([0.02, -0.01, 0.01, 0.004, -0.003, 0.002])) @ T_camera_lidar
    calibrator.run(inputs, init=Start.from_matrix(near, "warm-up"))


if __name__ == "__main__":  # pragma: no cover - run by start() in its own process
    tiny_job()
