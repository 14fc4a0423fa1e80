"""Scans in: input checks, per-point times, and the points of a scan that are used.

A scan is an array of shape (N, 3) or (N, 4) (x, y, z[, intensity]) or an object with
``points`` (and ``intensity``, ``times``) such as :class:`nbcalib.io.pointcloud.PointCloud`, in
the LiDAR frame at each point's time, metres. Rows with a non-finite value and points nearer to
the sensor than ``min_distance`` are dropped (``nbcalib.kernels.ct_icp._select_points``). A
scan without per-point times gets them from the azimuth of a spinning LiDAR
(:func:`synthesize_times_from_azimuth`); the registration uses them normalised to [0, 1] over
the scan (:func:`normalized_scan_times`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from nbcalib.progress import Progress

__all__ = ["normalized_scan_times", "synthesize_times_from_azimuth"]

ProgressCallback = Callable[[int, "int | None"], None]


@dataclass
class _Scan:
    """One input scan, checked for shapes (not yet for finiteness)."""

    points: np.ndarray  # (N, 3) float64, C-contiguous
    intensity: np.ndarray  # (N,) float64
    times: np.ndarray | None  # (N,) float64 or None


@dataclass
class _Prepared:
    """A scan ready for registration: its points at or beyond min_distance, with their times."""

    n_in: int  # finite points in the input scan
    points: np.ndarray  # (N, 3) points at or beyond min_distance from the sensor
    intensity: np.ndarray  # (N,)
    s: np.ndarray  # (N,) normalised times
    duration: float  # seconds between the first and the last point of the whole scan
    registration: np.ndarray  # (M, 3) the points used for registration
    registration_s: np.ndarray  # (M,) their normalised times


def _scan_arrays(scan: Any, index: int) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """(points (N, 3), intensity (N,) or None, times (N,) or None) of one scan-like input."""
    if isinstance(scan, np.ndarray) or isinstance(scan, list | tuple):
        array = np.asarray(scan, dtype=np.float64)
        if array.ndim != 2 or array.shape[1] not in (3, 4):
            raise ValueError(
                f"scan {index}: an array scan must have shape (N, 3) or (N, 4), got {array.shape}"
            )
        intensity = array[:, 3] if array.shape[1] == 4 else None
        return array[:, :3], intensity, None
    if not hasattr(scan, "points"):
        raise ValueError(
            f"scan {index}: expected an (N, 3|4) array or an object with .points "
            f"(e.g. nbcalib.io.pointcloud.PointCloud), got {type(scan).__name__}"
        )
    points = np.asarray(scan.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"scan {index}: points must have shape (N, 3), got {points.shape}")
    intensity = getattr(scan, "intensity", None)
    if intensity is None:
        intensity = getattr(scan, "intensities", None)
    times = getattr(scan, "times", None)
    return points, intensity, times


def _prepare_scan(scan: Any, times: Any, index: int) -> _Scan:
    points, intensity, own_times = _scan_arrays(scan, index)
    n = points.shape[0]
    if intensity is None:
        intensity = np.zeros(n)
    intensity = np.ascontiguousarray(intensity, dtype=np.float64).reshape(-1)
    if intensity.shape[0] != n:
        raise ValueError(f"scan {index}: {intensity.shape[0]} intensities for {n} points")
    if times is None:
        times = own_times
    if times is not None:
        times = np.ascontiguousarray(times, dtype=np.float64).reshape(-1)
        if times.shape[0] != n:
            raise ValueError(f"scan {index}: {times.shape[0]} point times for {n} points")
    return _Scan(np.ascontiguousarray(points, dtype=np.float64), intensity, times)


def _select(scan: _Scan, min_distance: float, sweep: tuple[float, bool, float] | None = None):
    """Finite points at or beyond ``min_distance`` (wraps ``ct_icp._select_points``).

    With ``sweep = (frame_rate, clockwise, start_azimuth_deg)`` (Hz, rotation sense, degrees),
    also their normalised times: the scan's own, or synthesised from the azimuth with those
    settings (:func:`synthesize_times_from_azimuth`). Returns (points, intensity, s, number of
    finite points, duration).
    """
    from nbcalib.kernels.ct_icp import _select_points

    has_times = scan.times is not None
    times = scan.times if has_times else np.zeros(0)
    if sweep is None:
        frame_rate, clockwise, start = 1.0, True, 0.0
    else:
        frame_rate, clockwise, start_azimuth_deg = sweep
        start = math.radians(start_azimuth_deg)
    return _select_points(
        scan.points,
        scan.intensity,
        times,
        has_times,
        frame_rate,
        clockwise,
        start,
        min_distance * min_distance,
        sweep is not None,
    )


def _check_min_distance(min_distance: float) -> None:
    if not (np.isfinite(min_distance) and min_distance >= 0):
        raise ValueError(f"min_distance must be >= 0, got {min_distance!r}")


def _points_arg(points: Any, name: str) -> np.ndarray:
    points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError(f"{name} must be finite")
    return points


def _iterate_scans(scans: Iterable, times: Sequence | None) -> Iterable[tuple[int, Any, Any]]:
    """Pairs (scan, times) with a clear error when the two sequences differ in length."""
    if times is None:
        for k, scan in enumerate(scans):
            yield k, scan, None
        return
    if hasattr(scans, "__len__") and len(scans) != len(times):
        raise ValueError(f"times has {len(times)} entries for {len(scans)} scans")
    times_iter = iter(times)
    k = -1
    for k, scan in enumerate(scans):
        try:
            t = next(times_iter)
        except StopIteration:
            raise ValueError(f"times has {k} entries, fewer than the scans") from None
        yield k, scan, t
    if next(times_iter, None) is not None:
        raise ValueError(f"times has more entries than the {k + 1} scans")


class _Progress:
    """A ``progress=`` argument: a callback ``(done, total)``, a display (``True``), or nothing."""

    def __init__(self, progress: bool | ProgressCallback | None, total: int | None, label: str):
        self.callback = progress if callable(progress) else None
        self.display = Progress(total, label, enabled=progress is True)

    def __call__(self, done: int) -> None:
        if self.callback is not None:
            self.callback(done, self.display.total)
        self.display.update(done - self.display.done, "scans")

    def close(self, failed: bool = False) -> None:
        self.display.close(failed)


def synthesize_times_from_azimuth(
    points: Any,
    frame_rate: float,
    *,
    clockwise: bool = True,
    start_azimuth_deg: float = 180.0,
) -> np.ndarray:
    """Per-point times of a spinning LiDAR sweep, from each point's azimuth.

    For files without times (KITTI ``.bin``): the head turns once per scan at constant rate, so a
    point's time is the angle the head turned from the start azimuth to the point's azimuth,
    divided by the angular rate ``2 pi frame_rate``. Velodyne and Ouster turn clockwise seen
    from above (azimuth ``atan2(y, x)`` decreasing), and KITTI's sweeps start and end behind the
    sensor (``start_azimuth_deg=180``). The rows of a KITTI scan are stored ring by ring, each
    ring running in *increasing* azimuth from behind: that is the reverse of acquisition order
    within a ring, and the benchmark (``docs/BENCHMARKS.md``) confirms clockwise times register
    better on the real frames.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        One sweep in the LiDAR frame (x forward, y left, z up), metres.
    frame_rate : float
        Sweeps per second, Hz.
    clockwise : bool
        Rotation sense seen from above.
    start_azimuth_deg : float
        Azimuth where a sweep starts, degrees (0 = forward, 90 = left).

    Returns
    -------
    ndarray of shape (N,), float64
        Seconds from the sweep start, in ``[0, 1 / frame_rate)``.
    """
    points = _points_arg(points, "points")
    frame_rate = float(frame_rate)
    if not (np.isfinite(frame_rate) and frame_rate > 0):
        raise ValueError(f"frame_rate must be a positive number of Hz, got {frame_rate!r}")
    azimuth = np.arctan2(points[:, 1], points[:, 0])
    turned = (
        np.radians(start_azimuth_deg) - azimuth
        if clockwise
        else azimuth - np.radians(start_azimuth_deg)
    )
    fraction = np.mod(turned, 2.0 * np.pi) / (2.0 * np.pi)
    fraction = np.where(fraction >= 1.0, 0.0, fraction)  # mod can round up to 2 pi
    return fraction / frame_rate


def normalized_scan_times(times: Any) -> tuple[np.ndarray, float]:
    """Normalised times ``s = (t - t_min) / (t_max - t_min)`` in [0, 1] and the duration.

    A scan whose points all share one time gets ``s = 0`` and duration 0.

    Parameters
    ----------
    times : array_like of shape (N,)
        Per-point times, seconds; finite.

    Returns
    -------
    s : ndarray of shape (N,), float64
    duration : float
        ``t_max - t_min``, seconds.
    """
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    if times.size == 0:
        return np.zeros(0), 0.0
    if not np.isfinite(times).all():
        raise ValueError("point times must be finite")
    t_min, t_max = float(times.min()), float(times.max())
    duration = t_max - t_min
    if duration <= 0.0:
        return np.zeros(times.shape[0]), 0.0
    return np.ascontiguousarray((times - t_min) / duration), duration
