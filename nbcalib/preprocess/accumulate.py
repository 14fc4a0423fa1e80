"""Dense clouds by static accumulation, and the dense-cloud result (paper section III-C).

A single LiDAR scan is too sparse to render a useful intensity image, so the method accumulates
several seconds of scans into one dense cloud, expressed in the LiDAR frame at the start of the
first scan (the frame the camera image pairs with), a :class:`DenseCloud`:

- :func:`integrate_static`, for non-repetitive LiDARs held still (Livox): every scan is already
  in that frame; the points are simply accumulated and de-duplicated on a fine voxel grid
  (:func:`nbcalib.odometry.voxelmap.voxel_deduplicate`).
- :func:`nbcalib.odometry.integrate_dynamic`, for spinning LiDARs moved by hand or on a vehicle
  (Velodyne, Ouster): LiDAR odometry by continuous-time ICP, then deskewing
  (:mod:`nbcalib.odometry`).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from nbcalib.errors import InputError
from nbcalib.odometry.config import DEFAULT_MIN_DISTANCE, DEFAULT_VOXEL_SIZE
from nbcalib.odometry.scans import (
    ProgressCallback,
    _check_min_distance,
    _iterate_scans,
    _prepare_scan,
    _Progress,
    _select,
)
from nbcalib.odometry.voxelmap import _VoxelAccumulator

__all__ = ["DenseCloud", "integrate_static"]


@dataclass(frozen=True, eq=False)
class DenseCloud:
    """An accumulated point cloud in the LiDAR frame at the start of the first scan.

    Attributes
    ----------
    points : ndarray of shape (N, 3), float64
        One point per occupied output voxel, in the LiDAR frame at the start of the first scan
        (``first``), metres; ordered by first appearance of the voxel (scan order, then point
        order within a scan).
    intensity : ndarray of shape (N,), float64
        Raw intensity of each point as read (not equalised): the voxel's mean or last value.
    T_first_scanbegin, T_first_scanend : ndarray of shape (K, 4, 4), float64
        Pose of the LiDAR at the first and at the last point of each input scan, in the frame
        ``first``; identities for :func:`integrate_static`. A scan that could not be used
        (empty, or too few matches) has its predicted poses.
    stats : dict of str to ndarray
        Per-scan diagnostics, arrays of shape (K,): ``points_in`` (finite input points),
        ``points_used`` (accumulated); for dynamic integration also ``iterations``,
        ``correspondences`` and ``residual_rms`` (metres, weighted) of the last iteration,
        and ``registered`` (bool).
    """

    points: np.ndarray
    intensity: np.ndarray
    T_first_scanbegin: np.ndarray
    T_first_scanend: np.ndarray
    stats: dict[str, np.ndarray] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def pose_at(self, scan: int, fraction: float) -> np.ndarray:
        """``T_first_at``: the LiDAR pose at ``fraction`` of scan ``scan``'s sweep, in ``first``.

        The trajectory interpolated between the scan's begin and end pose (slerp + lerp,
        :func:`nbcalib.transforms.interpolate_pose`); ``fraction`` 0 is the scan's first point,
        1 its last. ``invert_T(pose_at(k, s)) @ p`` moves the cloud into the LiDAR frame at that
        time (the frame of a camera image taken then).
        """
        from nbcalib.transforms import interpolate_pose

        if not 0 <= scan < self.T_first_scanbegin.shape[0]:
            raise ValueError(f"scan {scan} out of range: {self.T_first_scanbegin.shape[0]} scans")
        return interpolate_pose(self.T_first_scanbegin[scan], self.T_first_scanend[scan], fraction)


def integrate_static(
    scans: Iterable,
    *,
    voxel_size: float = DEFAULT_VOXEL_SIZE,
    min_distance: float = DEFAULT_MIN_DISTANCE,
    dedup: str = "mean",
    progress: bool | ProgressCallback | None = None,
) -> DenseCloud:
    """Accumulate scans of a LiDAR at rest into one dense cloud (reference section 3.1).

    Every scan is taken to be in the same LiDAR frame (the sensor did not move); points with a
    range below ``min_distance`` are dropped and the rest are de-duplicated on a voxel grid
    (:func:`~nbcalib.odometry.voxelmap.voxel_deduplicate`).

    Parameters
    ----------
    scans : iterable
        Scans in time order, each an array of shape (N, 3) or (N, 4) (x, y, z[, intensity]) or an
        object with ``points`` (N, 3) and ``intensity`` (N,) (``nbcalib.io.pointcloud.PointCloud``);
        LiDAR frame, metres. Rows with a non-finite value are dropped. Scans without intensity
        get 0.
    voxel_size : float
        Output voxel, metres; 0.002 as the reference CLI.
    min_distance : float
        Minimum range, metres.
    dedup : str
        ``"mean"`` (default: order-independent, averages noise) or ``"last"`` (the reference).
    progress : bool or callable, optional
        ``True`` for a progress bar on stderr, or a callback ``(done, total)``.

    Returns
    -------
    DenseCloud
        In the LiDAR frame; poses are identities.

    Raises
    ------
    InputError
        No scan, or no finite point at or beyond ``min_distance`` in any scan.
    """
    _check_min_distance(min_distance)
    accumulator = _VoxelAccumulator(voxel_size, dedup)
    n_scans = len(scans) if hasattr(scans, "__len__") else None
    report = _Progress(progress, n_scans, "integrate")
    points_in, points_used = [], []
    for k, raw, _ in _iterate_scans(scans, None):
        points, intensity, _, n_finite, _ = _select(_prepare_scan(raw, None, k), min_distance)
        if k == 0 and n_scans:  # size the table for all scans at once (no regrowth)
            accumulator.reserve(n_scans * points.shape[0])
        accumulator.add(points, intensity)
        points_in.append(n_finite)
        points_used.append(int(points.shape[0]))
        report(k + 1)
    report.close()
    if not points_in:
        raise InputError("no scans to integrate")
    points, intensity = accumulator.result()
    if points.shape[0] == 0:
        raise InputError(
            f"no finite point at a range of at least min_distance={min_distance} m in "
            f"{len(points_in)} scan(s)"
        )
    eye = np.broadcast_to(np.eye(4), (len(points_in), 4, 4)).copy()
    return DenseCloud(
        points=points,
        intensity=intensity,
        T_first_scanbegin=eye,
        T_first_scanend=eye.copy(),
        stats={"points_in": np.array(points_in), "points_used": np.array(points_used)},
    )
