"""Dense point clouds from many LiDAR scans (paper section III-C).

A single LiDAR scan is too sparse to render a useful intensity image, so the method accumulates
several seconds of scans into one dense cloud, expressed in the LiDAR frame at the start of the
first scan (the frame the camera image pairs with):

- :func:`integrate_static`, for non-repetitive LiDARs held still (Livox): every scan is already
  in that frame; the points are simply accumulated and de-duplicated on a fine voxel grid.
- :func:`integrate_dynamic`, for spinning LiDARs moved by hand or on a vehicle (Velodyne,
  Ouster): continuous-time ICP estimates, for each scan, the pose at its first and at its last
  point; each point is then moved with the pose interpolated at its own time (deskewing) into the
  frame of the first scan, and accumulated as in the static case.

Continuous-time ICP, step by step for scan ``k`` (:class:`DynamicIntegrationConfig` holds the
knobs):

1. **Predict** the begin and end poses at constant velocity: the scan begins where the previous
   one ended and moves as the previous one did (same body-frame rotation and translation,
   scaled by the ratio of the scan durations).
2. **Downsample** the scan for registration to about ``registration_points`` points spread over
   ``registration_voxel_size`` voxels (:func:`stratified_downsample`).
3. **Register** against the local map, an iVox-like voxel hash with a linear container of points
   per voxel (:class:`VoxelMap`): Gauss-Newton on the 12 parameters of the two poses, with the
   point-to-plane residuals of :mod:`nbcalib.kernels.ct_icp` (plane of the ``knn`` nearest map
   points, CT-ICP planarity weight, thickness gate, Geman-McClure robust kernel), a strong prior
   that the scan begins where the previous one ended (continuity), and a weak prior on the
   intra-scan motion (see ``motion_prior``). Planes are looked up again only when the points
   have moved (``reassociation_distance``).
4. **Deskew** the full-resolution scan with the final poses, accumulate it on the output voxel
   grid, and insert it into the map (which forgets voxels beyond ``map_max_distance``).

The first scan defines the output frame: its begin pose is the identity. Its end pose is taken as
the begin pose of the second scan, bootstrapped by a rigid alignment of the two raw scans (equal
to the motion over one scan at constant velocity) when the second scan's own registration says
the first one was moving, and the identity (at rest) otherwise; the map is then rebuilt from the
first scan deskewed with it and the second scan is registered again (``refine_first_scan``).

The robust kernel narrows to the noise: once a scan has converged with the kernel of scale
``robust_scale`` (and moved as predicted), the planes are looked up again with a scale of
``robust_sigmas`` times the noise of the point-to-plane distances of the previous scan. Points
matched to the wrong surface (a few centimetres off at edges and small objects) do not vanish at
the true pose; with a 10 cm kernel they biased every scan by millimetres, the same way at rest
as in motion.

Differences from the reference toolbox (``koide3/direct_visual_lidar_calibration``, which uses
CT-GICP through GTSAM), each deliberate:

- point-to-plane residuals against a plane fitted in the map at each query, instead of GICP with
  plane-regularised covariances: the same geometry for planar scenes, no per-point covariances;
- the per-point pose interpolates rotation by slerp and translation linearly in the residuals
  too (the reference's factor uses the SE(3) geodesic there and slerp + lerp only to deskew);
- nearest neighbours searched exactly within ``max_correspondence_distance`` in the 27 voxels
  around a point (the reference uses the 7 face neighbours, an approximation);
- the map forgets voxels by distance to the sensor rather than by least-recent use;
- the prior on the intra-scan motion pulls towards the constant-velocity prediction
  (``motion_prior="constant_velocity"``, as CT-ICP) and is weak, instead of pulling strongly
  towards no motion (the reference's BetweenFactor, which under-deskews fast motion and, in a
  street, decides the forward motion instead of the data); ``motion_prior="zero"`` with a large
  ``motion_prior_weight`` restores the reference's behaviour; the prior on the begin pose is
  strong (continuity) where the reference's is weak;
- a moving first scan is deskewed (the reference assumes the rig at rest at the start);
- constant-velocity prediction at full rate (the reference extrapolates 0.75 of the last motion);
- ``min_distance`` is the range from the sensor when the point was taken (the reference measures
  it from the origin of the first scan, which keeps the vehicle's own returns after it moved);
- the output is ordered by first appearance of each voxel, not in hash-map order, so the same
  input always gives the same ``.ply`` and index map; voxel values are averaged by default.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nbcalib.errors import InputError

__all__ = [
    "DEDUP_RULES",
    "DenseCloud",
    "DynamicIntegrationConfig",
    "VoxelMap",
    "deskew",
    "integrate_dynamic",
    "integrate_static",
    "local_thickness",
    "normalized_scan_times",
    "stratified_downsample",
    "synthesize_times_from_azimuth",
    "voxel_deduplicate",
    "voxel_downsample",
]

#: Voxel de-duplication rules: ``"mean"`` (default) or ``"last"`` (the reference's overwrite).
DEDUP_RULES = ("mean", "last")

#: Default output voxel, metres: the reference CLI's ``--voxel_resolution`` (its parameter
#: structs say 0.05 m, but the command line overrides them with 0.002 m).
DEFAULT_VOXEL_SIZE = 0.002
#: Default minimum range, metres (the reference CLI's ``--min_distance``).
DEFAULT_MIN_DISTANCE = 1.0

ProgressCallback = Callable[[int, "int | None"], None]


# ---------------------------------------------------------------------------------------------
# Results and configuration
# ---------------------------------------------------------------------------------------------


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


@dataclass(frozen=True)
class DynamicIntegrationConfig:
    """Knobs of :func:`integrate_dynamic` (continuous-time ICP and accumulation).

    Parameters
    ----------
    voxel_size : float
        Output voxel, metres (reference CLI default 0.002).
    min_distance : float
        Points closer than this to the sensor are dropped, metres.
    dedup : str
        Output voxel rule, ``"mean"`` or ``"last"`` (:func:`voxel_deduplicate`).
    frame_rate : float
        Scans per second; only used to synthesise per-point times from the azimuth when a scan
        carries none (:func:`synthesize_times_from_azimuth`).
    clockwise : bool
        Rotation sense for synthesised times (seen from above; Velodyne and Ouster: True).
    start_azimuth_deg : float
        Azimuth of the first point of a sweep for synthesised times, degrees (180: behind).
    registration_voxel_size : float
        Voxel of the registration downsampling, metres: each voxel keeps an equal share of its
        points (evenly spread in acquisition order), the share chosen so that about
        ``registration_points`` points remain.
    registration_points : int
        Target number of points per scan in the registration.
    map_voxel_size : float
        Voxel of the local map, metres (the reference's iVox uses 1.0).
    map_max_points_per_voxel : int
        Capacity of each voxel's linear container.
    map_min_spacing : float
        A point closer than this to a point of its voxel is not added to the map, metres.
    map_max_distance : float
        Map voxels farther than this from the sensor are forgotten, metres.
    knn : int
        Map points used to fit each plane.
    min_neighbors : int
        Fewer neighbours than this within ``max_correspondence_distance``: no residual.
    max_correspondence_distance : float
        Neighbour search radius, metres; at most ``map_voxel_size`` (the search is then exact).
    max_plane_thickness : float
        A map patch whose points spread more than this off their plane (standard deviation)
        gives no residual, metres: edges, corners and clutter are not planes.
    robust_scale : float
        Largest scale ``c`` of the Geman-McClure kernel on point-to-plane distances, metres.
    robust_sigmas : float
        Once a scan has converged with ``robust_scale`` and moved as predicted (to within
        ``robust_scale``), its planes are looked up again and the registration finished with a
        kernel of this many robust standard deviations (1.4826 median absolute value) of the
        point-to-plane distances of the previous registration, between 1 cm and
        ``robust_scale``: the kernel follows the sensor's noise, and points matched to the
        wrong surface, which bias a wide kernel, get little weight. 0 keeps ``robust_scale``.
    robust_anneal : float
        While the velocity is still unknown (the first scans), the first plane lookup of a scan
        uses a kernel ``robust_anneal`` times wider, halved at each new lookup down to
        ``robust_scale`` (graduated non-convexity: a poor prediction must not silence the few
        planes that observe it). 1 disables it.
    max_iterations : int
        Gauss-Newton iterations per scan.
    convergence_tolerance : float
        Stop when an update moves a source point at the median range by less than this, metres.
    reassociation_distance : float
        Planes are looked up again in the map once the source points (at the median range) have
        moved by more than this since the last lookup, metres (and once more at convergence if
        they moved by more than a fifth of it).
    begin_prior_weight : float
        Weight of the prior that the scan begins where the previous one ended (continuity),
        per metre^2 / radian^2, in the units of the data term (a residual of one planar point at
        full weight counts 1 per m^2; with 1 cm point noise, a weight ``w`` is a prior of
        standard deviation ``1 cm / sqrt(w)``).
    motion_prior : str
        ``"constant_velocity"``: the intra-scan motion is pulled towards the predicted one;
        ``"zero"``: towards no motion (the reference's BetweenFactor).
    motion_prior_weight : float
        Weight of that prior, same units as ``begin_prior_weight``. Keep it weak: along the
        direction of travel in a street, point-to-plane residuals carry little information
        about the motion within a scan, and a strong prior then decides it.
    min_correspondences : int
        A scan with fewer residuals than this is not registered (its predicted poses are kept
        and its points are accumulated with them).
    refine_first_scan : bool
        Deskew the first scan with the begin pose of the second and register the second again.
    background_accumulation : bool
        De-duplicate the deskewed points on a second thread while the next scan is registered
        (same result: scans are folded in order).
    threads : int
        1 or 2: with 2, the plane lookups of a scan are split between two threads (numba kernels
        release the GIL; same result).
    parallel : bool
        Use numba's ``prange`` kernels for deskewing and association instead (same result, bit
        for bit). Off by default: on a loaded 2-core machine numba's OpenMP workers spin and can
        stall the process (``docs/BENCHMARKS.md``).
    """

    voxel_size: float = DEFAULT_VOXEL_SIZE
    min_distance: float = DEFAULT_MIN_DISTANCE
    dedup: str = "mean"
    frame_rate: float = 10.0
    clockwise: bool = True
    start_azimuth_deg: float = 180.0
    registration_voxel_size: float = 0.5
    registration_points: int = 4000
    map_voxel_size: float = 1.0
    map_max_points_per_voxel: int = 20
    map_min_spacing: float = 0.1
    map_max_distance: float = 100.0
    knn: int = 10
    min_neighbors: int = 5
    max_correspondence_distance: float = 1.0
    max_plane_thickness: float = 0.03
    robust_scale: float = 0.1
    robust_sigmas: float = 3.0
    robust_anneal: float = 4.0
    max_iterations: int = 20
    convergence_tolerance: float = 1e-4
    reassociation_distance: float = 0.05
    begin_prior_weight: float = 100.0
    motion_prior: str = "constant_velocity"
    motion_prior_weight: float = 1.0
    min_correspondences: int = 100
    refine_first_scan: bool = True
    background_accumulation: bool = True
    threads: int = 2
    parallel: bool = False

    def __post_init__(self):
        positive = (
            "voxel_size",
            "frame_rate",
            "registration_voxel_size",
            "map_voxel_size",
            "map_max_distance",
            "max_correspondence_distance",
            "robust_scale",
            "max_plane_thickness",
            "convergence_tolerance",
            "reassociation_distance",
        )
        for name in positive:
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be a positive number, got {value!r}")
        non_negative = ("min_distance", "map_min_spacing", "begin_prior_weight", "robust_sigmas")
        if not (np.isfinite(self.robust_anneal) and self.robust_anneal >= 1.0):
            raise ValueError(f"robust_anneal must be >= 1, got {self.robust_anneal!r}")
        for name in (*non_negative, "motion_prior_weight"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a non-negative number, got {value!r}")
        for name in ("registration_points", "map_max_points_per_voxel", "knn", "min_neighbors"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"{name} must be a positive integer, got {getattr(self, name)!r}")
        if self.min_neighbors < 3 or self.min_neighbors > self.knn:
            raise ValueError(
                f"need 3 <= min_neighbors <= knn, got {self.min_neighbors}, {self.knn}"
            )
        if self.threads not in (1, 2):
            raise ValueError(f"threads must be 1 or 2, got {self.threads!r}")
        if self.max_iterations < 1:
            raise ValueError(f"max_iterations must be >= 1, got {self.max_iterations}")
        if self.max_correspondence_distance > self.map_voxel_size:
            raise ValueError(
                "max_correspondence_distance must not exceed map_voxel_size (the neighbour "
                f"search covers one voxel around a point), got {self.max_correspondence_distance}"
                f" > {self.map_voxel_size}"
            )
        if self.dedup not in DEDUP_RULES:
            raise ValueError(f"dedup must be one of {DEDUP_RULES}, got {self.dedup!r}")
        if self.motion_prior not in ("constant_velocity", "zero"):
            raise ValueError(
                f"motion_prior must be 'constant_velocity' or 'zero', got {self.motion_prior!r}"
            )


# ---------------------------------------------------------------------------------------------
# Input checks
# ---------------------------------------------------------------------------------------------


@dataclass
class _Scan:
    """One input scan, checked for shapes (not yet for finiteness)."""

    points: np.ndarray  # (N, 3) float64, C-contiguous
    intensity: np.ndarray  # (N,) float64
    times: np.ndarray | None  # (N,) float64 or None


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


def _select(scan: _Scan, min_distance: float, config=None):
    """Finite points at or beyond ``min_distance`` (wraps ``ct_icp._select_points``).

    With a :class:`DynamicIntegrationConfig`, also their normalised times (the scan's own or
    synthesised from the azimuth). Returns (points, intensity, s, number of finite points,
    duration).
    """
    from nbcalib.kernels.ct_icp import _select_points

    has_times = scan.times is not None
    times = scan.times if has_times else np.zeros(0)
    if config is None:
        frame_rate, clockwise, start = 1.0, True, 0.0
    else:
        frame_rate = config.frame_rate
        clockwise = config.clockwise
        start = math.radians(config.start_azimuth_deg)
    return _select_points(
        scan.points,
        scan.intensity,
        times,
        has_times,
        frame_rate,
        clockwise,
        start,
        min_distance * min_distance,
        config is not None,
    )


def _check_voxel(voxel_size: float, name: str = "voxel_size") -> float:
    voxel_size = float(voxel_size)
    if not (np.isfinite(voxel_size) and voxel_size > 0):
        raise ValueError(f"{name} must be a positive number, got {voxel_size!r}")
    return voxel_size


def _check_extent(points: np.ndarray, voxel_size: float) -> None:
    """Voxel keys hold coordinates in [-2^20, 2^20) voxels: refuse points beyond that."""
    from nbcalib.kernels.voxelmap import COORD_LIMIT

    if points.size and np.abs(points).max() / voxel_size >= COORD_LIMIT - 2:
        raise ValueError(
            f"points reach {np.abs(points).max():.1f} m from the origin; at a voxel of "
            f"{voxel_size} m the voxel grid covers {(COORD_LIMIT - 2) * voxel_size:.1f} m"
        )


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
    """Progress reporting: a callback ``(done, total)``, a bar on stderr, or nothing."""

    def __init__(self, progress: bool | ProgressCallback | None, total: int | None, label: str):
        self.callback = progress if callable(progress) else None
        self.bar = progress is True
        self.total = total
        self.label = label

    def __call__(self, done: int) -> None:
        if self.callback is not None:
            self.callback(done, self.total)
        if self.bar:
            if self.total:
                width = 30
                filled = int(width * done / self.total)
                text = (
                    f"\r{self.label} [{'#' * filled}{'.' * (width - filled)}] {done}/{self.total}"
                )
            else:
                text = f"\r{self.label} {done} scans"
            sys.stderr.write(text)
            sys.stderr.flush()

    def close(self) -> None:
        if self.bar:
            sys.stderr.write("\n")
            sys.stderr.flush()


# ---------------------------------------------------------------------------------------------
# Voxel grids
# ---------------------------------------------------------------------------------------------


def voxel_downsample(points: Any, voxel_size: float) -> np.ndarray:
    """Indices of the first point in each voxel ``floor(p / voxel_size)``.

    Wraps :func:`nbcalib.kernels.voxelmap._voxel_first_indices`.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Points, any frame, metres; finite.
    voxel_size : float
        Voxel edge, metres.

    Returns
    -------
    ndarray of shape (M,), int64
        Index of the first point of each occupied voxel, voxels in order of first appearance
        (so the indices are increasing).
    """
    from nbcalib.kernels.voxelmap import _voxel_first_indices

    points = _points_arg(points, "points")
    return _voxel_first_indices(points, _check_voxel(voxel_size))


def stratified_downsample(points: Any, voxel_size: float, target: int) -> np.ndarray:
    """Indices of about ``target`` points spread evenly over the occupied voxels.

    Every voxel ``floor(p / voxel_size)`` keeps ``min(count, m)`` of its points, the ``m`` chosen
    as the smallest share that reaches ``target`` points in total (all points if there are fewer);
    a voxel with more than ``m`` points keeps ranks evenly spaced in input (acquisition) order.
    When there are more voxels than ``target``, the first point of each voxel is kept and that
    list is thinned evenly to ``target``. Deterministic, unlike the reference's random grid. Wraps
    :func:`nbcalib.kernels.voxelmap._voxel_ranks`.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Points, metres; finite.
    voxel_size : float
        Voxel edge, metres.
    target : int
        Wanted number of points (the result can exceed it by less than one point per voxel).

    Returns
    -------
    ndarray of shape (M,), int64
        Increasing indices into ``points``.
    """
    from nbcalib.kernels.voxelmap import _voxel_ranks

    points = _points_arg(points, "points")
    if points.shape[0] <= target:
        return np.arange(points.shape[0])
    slot, rank, counts = _voxel_ranks(points, _check_voxel(voxel_size))
    lo, hi = 1, int(counts.max())
    while lo < hi:  # smallest share m with sum(min(counts, m)) >= target
        mid = (lo + hi) // 2
        if np.minimum(counts, mid).sum() >= target:
            hi = mid
        else:
            lo = mid + 1
    c = counts[slot]
    keep = np.flatnonzero((c <= lo) | ((rank + 1) * lo // c > rank * lo // c))
    if keep.shape[0] > target:  # more voxels than target: every voxel's first point, thinned
        keep = keep[np.linspace(0, keep.shape[0] - 1, target).round().astype(np.int64)]
    return keep


class _VoxelAccumulator:
    """One value per output voxel, grown scan by scan (wraps ``voxelmap._accumulate``)."""

    def __init__(self, voxel_size: float, rule: str, capacity: int = 1 << 16):
        if rule not in DEDUP_RULES:
            raise ValueError(f"dedup must be one of {DEDUP_RULES}, got {rule!r}")
        from nbcalib.kernels.voxelmap import RULE_LAST, RULE_MEAN, _empty_table

        self.voxel_size = _check_voxel(voxel_size)
        self.rule = RULE_MEAN if rule == "mean" else RULE_LAST
        capacity = max(int(capacity), 16)
        self.n_slots = np.zeros(1, dtype=np.int64)
        self.keys = np.empty(capacity, dtype=np.int64)
        self.values = np.empty((capacity, 5))
        self.table = _empty_table(capacity)

    def reserve(self, extra: int) -> None:
        """Make room for ``extra`` more voxels (capacity at least doubles when it grows)."""
        from nbcalib.kernels.voxelmap import _empty_table, _rehash

        n = int(self.n_slots[0])
        need = n + extra
        if need <= self.keys.shape[0]:
            return
        capacity = max(need, 2 * self.keys.shape[0])
        keys = np.empty(capacity, dtype=np.int64)
        values = np.empty((capacity, 5))
        keys[:n], values[:n] = self.keys[:n], self.values[:n]
        self.keys, self.values = keys, values
        self.table = _empty_table(capacity)
        _rehash(self.keys, n, self.table)

    def add(self, points: np.ndarray, intensity: np.ndarray) -> None:
        from nbcalib.kernels.voxelmap import _accumulate

        _check_extent(points, self.voxel_size)
        self.reserve(points.shape[0])
        _accumulate(
            self.table,
            self.keys,
            self.values,
            self.n_slots,
            points,
            intensity,
            self.voxel_size,
            self.rule,
        )

    def result(self) -> tuple[np.ndarray, np.ndarray]:
        from nbcalib.kernels.voxelmap import RULE_MEAN

        n = int(self.n_slots[0])
        values = self.values[:n, :4]
        if self.rule == RULE_MEAN:
            values = values / self.values[:n, 4:5]
        return np.ascontiguousarray(values[:, :3]), np.ascontiguousarray(values[:, 3])


def voxel_deduplicate(
    points: Any, intensity: Any, *, voxel_size: float = DEFAULT_VOXEL_SIZE, rule: str = "mean"
) -> tuple[np.ndarray, np.ndarray]:
    """Keep one point per voxel ``floor(p / voxel_size)``.

    Wraps :func:`nbcalib.kernels.voxelmap._accumulate`.

    ``rule="mean"`` (the default) averages the points and intensities that fall into a voxel:
    the result does not depend on the order of the scans, averages out range and intensity noise
    of repeated hits (a static Livox hits the same spots many times), and stays inside the voxel.
    ``rule="last"`` keeps the last point, as the reference toolbox. Voxels are output in order of
    first appearance (the reference's hash-map order is unspecified), so the output, and the
    index map rendered from it, is the same for the same input.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Points, any frame, metres; finite.
    intensity : array_like of shape (N,)
        Their intensities.
    voxel_size : float
        Voxel edge, metres.
    rule : str
        ``"mean"`` or ``"last"``.

    Returns
    -------
    points : ndarray of shape (M, 3), float64
    intensity : ndarray of shape (M,), float64
    """
    points = _points_arg(points, "points")
    intensity = np.ascontiguousarray(intensity, dtype=np.float64).reshape(-1)
    if intensity.shape[0] != points.shape[0]:
        raise ValueError(f"{intensity.shape[0]} intensities for {points.shape[0]} points")
    accumulator = _VoxelAccumulator(voxel_size, rule, capacity=max(points.shape[0], 16))
    accumulator.add(points, intensity)
    return accumulator.result()


class VoxelMap:
    """iVox-like local map: a voxel hash with a linear container of points per voxel.

    Wraps :mod:`nbcalib.kernels.voxelmap` (``_voxelmap_insert``, ``_knn_one``, ``_rehash``);
    the semantics are in that module's docstring and the slow reference is
    :class:`nbcalib.reference.integrate.VoxelMapReference`.

    Parameters
    ----------
    voxel_size : float
        Voxel edge, metres.
    max_points_per_voxel : int
        Capacity of each voxel's container.
    min_spacing : float
        A point closer than this to a point already in its voxel is not added, metres.
    capacity : int
        Initial number of voxels (grows as needed).
    """

    def __init__(
        self,
        voxel_size: float,
        *,
        max_points_per_voxel: int = 20,
        min_spacing: float = 0.0,
        capacity: int = 4096,
    ):
        from nbcalib.kernels.voxelmap import _empty_table

        self.voxel_size = _check_voxel(voxel_size)
        if int(max_points_per_voxel) < 1:
            raise ValueError(f"max_points_per_voxel must be >= 1, got {max_points_per_voxel}")
        if not (np.isfinite(min_spacing) and min_spacing >= 0):
            raise ValueError(f"min_spacing must be >= 0, got {min_spacing}")
        self.max_points_per_voxel = int(max_points_per_voxel)
        self.min_spacing = float(min_spacing)
        capacity = max(int(capacity), 16)
        self.n_slots = np.zeros(1, dtype=np.int64)
        self.keys = np.empty(capacity, dtype=np.int64)
        self.counts = np.zeros(capacity, dtype=np.int64)
        self.store = np.zeros((capacity, self.max_points_per_voxel, 3))
        self.table = _empty_table(capacity)

    @property
    def n_voxels(self) -> int:
        """Number of occupied voxels."""
        return int(self.n_slots[0])

    def __len__(self) -> int:
        """Number of stored points."""
        return int(self.counts[: self.n_voxels].sum())

    def _resize(self, capacity: int) -> None:
        from nbcalib.kernels.voxelmap import _empty_table, _rehash

        n = self.n_voxels
        keys = np.empty(capacity, dtype=np.int64)
        counts = np.zeros(capacity, dtype=np.int64)
        store = np.zeros((capacity, self.max_points_per_voxel, 3))
        keys[:n], counts[:n], store[:n] = self.keys[:n], self.counts[:n], self.store[:n]
        self.keys, self.counts, self.store = keys, counts, store
        self.table = _empty_table(capacity)
        _rehash(self.keys, n, self.table)

    def insert(self, points: Any) -> int:
        """Add points (M, 3) (map frame, metres); returns how many were stored."""
        from nbcalib.kernels.voxelmap import _voxelmap_insert

        points = _points_arg(points, "points")
        _check_extent(points, self.voxel_size)
        need = self.n_voxels + points.shape[0]
        if need > self.keys.shape[0]:
            self._resize(max(need, 2 * self.keys.shape[0]))
        return int(
            _voxelmap_insert(
                self.table,
                self.keys,
                self.counts,
                self.store,
                self.n_slots,
                points,
                self.voxel_size,
                self.min_spacing,
            )
        )

    def remove_far(self, center: Any, max_distance: float) -> None:
        """Forget voxels whose centre is farther than ``max_distance`` from ``center`` (3,)."""
        from nbcalib.kernels.voxelmap import _unpack_all

        n = self.n_voxels
        centers = (_unpack_all(self.keys[:n]) + 0.5) * self.voxel_size
        keep = np.linalg.norm(centers - np.asarray(center, dtype=np.float64), axis=1)
        keep = keep <= max_distance
        if keep.all():
            return
        m = int(keep.sum())
        self.keys[:m] = self.keys[:n][keep]
        self.counts[:m] = self.counts[:n][keep]
        self.store[:m] = self.store[:n][keep]
        self.n_slots[0] = m
        self._resize(self.keys.shape[0])

    def points(self) -> tuple[np.ndarray, np.ndarray]:
        """Stored points (M, 3) and their flat indices (M,) ``slot * P + j``, in slot order."""
        n, P = self.n_voxels, self.max_points_per_voxel
        mask = np.arange(P)[None, :] < self.counts[:n, None]
        flat = np.flatnonzero(mask.reshape(-1))
        return self.store[:n].reshape(-1, 3)[flat], flat

    def point(self, flat: Any) -> np.ndarray:
        """Stored points at flat indices (any shape) -> (..., 3)."""
        return self.store.reshape(-1, 3)[np.asarray(flat)]

    def knn(self, queries: Any, k: int, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest stored points to each query within ``max_distance``.

        Parameters
        ----------
        queries : array_like of shape (Q, 3)
            Query points, map frame, metres.
        k : int
            Neighbours per query.
        max_distance : float
            Search radius, metres; at most ``voxel_size`` (exact search).

        Returns
        -------
        indices : ndarray of shape (Q, k), int64
            Flat indices (see :meth:`points`), ascending distance, ties by index; -1 past the
            last neighbour found.
        distances_sq : ndarray of shape (Q, k), float64
            Squared distances, m^2; inf past the last neighbour.
        """
        from nbcalib.kernels.voxelmap import _voxelmap_knn

        queries = _points_arg(queries, "queries")
        if int(k) < 1:
            raise ValueError(f"k must be >= 1, got {k}")
        if not (0 < max_distance <= self.voxel_size):
            raise ValueError(
                f"max_distance must be in (0, voxel_size={self.voxel_size}], got {max_distance}"
            )
        _check_extent(queries, self.voxel_size)
        return _voxelmap_knn(
            self.table,
            self.counts,
            self.store,
            self.voxel_size,
            queries,
            int(k),
            float(max_distance),
        )


# ---------------------------------------------------------------------------------------------
# Per-point times and deskewing
# ---------------------------------------------------------------------------------------------


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


def _pose_parts(T: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    from nbcalib.transforms import validate_T

    T = validate_T(T, name=name)
    return np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3])


def _relative_rotation_vector(R_b: np.ndarray, R_e: np.ndarray) -> np.ndarray:
    from nbcalib.kernels.lie import so3_log

    return so3_log(np.ascontiguousarray(R_b.T @ R_e))


def deskew(
    points: Any, s: Any, T_world_begin: Any, T_world_end: Any, *, parallel: bool = False
) -> np.ndarray:
    """Move each point of a scan with the pose interpolated at its own time.

    ``p_world = T(s) p`` with ``T(s)`` = slerp of the rotations and lerp of the translations of
    ``T_world_begin`` and ``T_world_end`` (``docs/conventions.md``). Wraps
    :func:`nbcalib.kernels.ct_icp._deskew`; the reference is
    :func:`nbcalib.reference.integrate.deskew`.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        The scan in the LiDAR frame at each point's time, metres.
    s : array_like of shape (N,)
        Normalised point times in [0, 1] (:func:`normalized_scan_times`).
    T_world_begin, T_world_end : array_like of shape (4, 4)
        LiDAR poses at ``s = 0`` and ``s = 1`` in the target frame ``world``.
    parallel : bool
        Use the parallel kernel (same result).

    Returns
    -------
    ndarray of shape (N, 3), float64
        The points in frame ``world``, metres.
    """
    from nbcalib.kernels.ct_icp import _deskew, _deskew_parallel

    points = _points_arg(points, "points")
    s = np.ascontiguousarray(s, dtype=np.float64).reshape(-1)
    if s.shape[0] != points.shape[0]:
        raise ValueError(f"{s.shape[0]} times for {points.shape[0]} points")
    if not np.isfinite(s).all():
        raise ValueError("s must be finite")
    R_b, t_b = _pose_parts(T_world_begin, "T_world_begin")
    R_e, t_e = _pose_parts(T_world_end, "T_world_end")
    out = np.empty_like(points)
    kernel = _deskew_parallel if parallel else _deskew
    kernel(points, s, R_b, t_b, t_e, _relative_rotation_vector(R_b, R_e), out)
    return out


# ---------------------------------------------------------------------------------------------
# Static integration
# ---------------------------------------------------------------------------------------------


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
    (:func:`voxel_deduplicate`).

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
    if not (np.isfinite(min_distance) and min_distance >= 0):
        raise ValueError(f"min_distance must be >= 0, got {min_distance!r}")
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


# ---------------------------------------------------------------------------------------------
# Dynamic integration: continuous-time ICP
# ---------------------------------------------------------------------------------------------


def _hat(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass
class _Registration:
    """Outcome of registering one scan."""

    T_begin: np.ndarray
    T_end: np.ndarray
    iterations: int
    correspondences: int
    residual_rms: float
    registered: bool


class _ContinuousTimeICP:
    """Scan-to-map continuous-time ICP and the accumulation it feeds (module docstring)."""

    def __init__(self, config: DynamicIntegrationConfig):
        from nbcalib.kernels import ct_icp

        self.config = config
        self.map = VoxelMap(
            config.map_voxel_size,
            max_points_per_voxel=config.map_max_points_per_voxel,
            min_spacing=config.map_min_spacing,
        )
        self.output = _VoxelAccumulator(config.voxel_size, config.dedup)
        self._worker = None
        self._pending = None
        self._pool = None
        if config.threads > 1:
            from concurrent.futures import ThreadPoolExecutor

            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="nbcalib-associate")
        if config.background_accumulation:
            from concurrent.futures import ThreadPoolExecutor

            self._worker = ThreadPoolExecutor(
                max_workers=1, thread_name_prefix="nbcalib-accumulate"
            )
        self._normal_equations = (
            ct_icp._normal_equations_parallel if config.parallel else ct_icp._normal_equations
        )
        self._associate = ct_icp._associate_parallel if config.parallel else ct_icp._associate
        self._deskew = ct_icp._deskew_parallel if config.parallel else ct_icp._deskew
        self.scans_inserted = 0
        self.noise_sigma = math.nan  # of the point-to-plane distances (``_update_noise``)

    # -- step 1: prediction ------------------------------------------------------------------
    @staticmethod
    def predict(
        previous: tuple[np.ndarray, np.ndarray, float] | None,
        end_of_last: np.ndarray,
        duration: float,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Predicted (T_begin, T_end) and the predicted body-frame motion (phi, d)."""
        from nbcalib.transforms import make_T, so3_exp

        T_begin = end_of_last.copy()
        if previous is None:
            return T_begin, T_begin.copy(), np.zeros(3), np.zeros(3)
        T_b, T_e, previous_duration = previous
        R_b, R_e = T_b[:3, :3], T_e[:3, :3]
        phi = _relative_rotation_vector(R_b, R_e)
        d = R_b.T @ (T_e[:3, 3] - T_b[:3, 3])
        scale = duration / previous_duration if previous_duration > 0 else 0.0
        phi, d = scale * phi, scale * d
        R = T_begin[:3, :3]
        T_end = make_T(R @ so3_exp(phi), T_begin[:3, 3] + R @ d)
        return T_begin, T_end, phi, d

    # -- step 2: downsampling ----------------------------------------------------------------
    def downsample(self, points: np.ndarray) -> np.ndarray:
        return stratified_downsample(
            points, self.config.registration_voxel_size, self.config.registration_points
        )

    # -- step 3: registration ----------------------------------------------------------------
    def register(
        self,
        points: np.ndarray,
        s: np.ndarray,
        T_begin: np.ndarray,
        T_end: np.ndarray,
        phi_pred: np.ndarray,
        d_pred: np.ndarray,
        *,
        begin_prior_weight: float | None = None,
        anneal: bool = False,
    ) -> _Registration:
        """Gauss-Newton on [v_b, w_b, v_e, w_e] from the predicted poses."""
        from nbcalib.kernels.ct_icp import PLANE_SIZE
        from nbcalib.kernels.lie import so3_exp as so3_exp_kernel

        config = self.config
        T_b_pred = T_begin.copy()
        T_b, T_e = T_begin.copy(), T_end.copy()
        if config.motion_prior == "zero":
            phi_pred, d_pred = np.zeros(3), np.zeros(3)
        planes = np.empty((points.shape[0], PLANE_SIZE))
        # lever arm turning a rotation update into a displacement: the median range (the
        # farthest points would make every update look large)
        reach = float(np.sqrt(np.median(np.einsum("ij,ij->i", points, points))))
        moved = math.inf  # how far the points moved since the planes were looked up
        associations, scale = 0, config.robust_scale
        target = self._target_scale()
        narrow = False
        used, cost, iterations = 0, 0.0, 0
        for iterations in range(1, config.max_iterations + 1):
            R_b, t_b = np.ascontiguousarray(T_b[:3, :3]), np.ascontiguousarray(T_b[:3, 3])
            R_e, t_e = np.ascontiguousarray(T_e[:3, :3]), np.ascontiguousarray(T_e[:3, 3])
            phi = _relative_rotation_vector(R_b, R_e)
            if moved > config.reassociation_distance:
                self._associate_rows(
                    points,
                    s,
                    R_b,
                    t_b,
                    t_e,
                    phi,
                    self._map_args(),
                    planes,
                )
                moved = 0.0
                # graduated robust kernel: wide at first (a poor prediction must not silence the
                # few planes that see it), halved at each new association down to robust_scale;
                # narrowed to the noise only once converged with robust_scale, since the
                # prediction can be off along a direction that few planes observe (the street
                # corridor), and a narrow kernel would silence them
                widen = config.robust_anneal / 2.0**associations if anneal else 1.0
                scale = (target if narrow else config.robust_scale) * max(1.0, widen)
                associations += 1
            H, g, cost, used = self._normal_equations(points, s, R_b, t_b, t_e, phi, planes, scale)
            if used < config.min_correspondences:
                return _Registration(T_begin, T_end, iterations, int(used), math.nan, False)
            w_begin = (
                config.begin_prior_weight if begin_prior_weight is None else begin_prior_weight
            )
            _add_priors(H, g, T_b, T_e, T_b_pred, phi, phi_pred, d_pred, w_begin, config)
            delta = _solve(H, g)
            T_b = _apply_increment(T_b, delta[:6], so3_exp_kernel)
            T_e = _apply_increment(T_e, delta[6:], so3_exp_kernel)
            step = max(
                np.linalg.norm(delta[0:3]) + reach * np.linalg.norm(delta[3:6]),
                np.linalg.norm(delta[6:9]) + reach * np.linalg.norm(delta[9:12]),
            )
            moved += step
            if step < config.convergence_tolerance:
                if moved <= 0.2 * config.reassociation_distance and scale <= target:
                    break
                # narrow only when the scan moved as predicted, to within robust_scale: after a
                # poor prediction (hard acceleration) a weak direction may still be unresolved
                narrow = narrow or (
                    scale <= config.robust_scale
                    and max(_pose_distance(T_b, T_begin, reach), _pose_distance(T_e, T_end, reach))
                    < config.robust_scale
                )
                moved = math.inf  # stale planes or a wide kernel: look them up once more
        rms = math.sqrt(cost / used) if used else math.nan
        self._update_noise(points, s, T_b, T_e, planes)
        return _Registration(T_b, T_e, iterations, int(used), rms, True)

    def _map_args(self) -> tuple:
        config = self.config
        return (
            self.map.table,
            self.map.counts,
            self.map.store,
            self.map.voxel_size,
            config.knn,
            config.max_correspondence_distance,
            config.min_neighbors,
            config.max_plane_thickness,
        )

    def _target_scale(self) -> float:
        """Scale of the Geman-McClure kernel after the first plane lookup of a scan.

        ``robust_sigmas`` times the noise of the point-to-plane distances measured at the end
        of the previous registration (:meth:`_update_noise`), between
        :data:`_MIN_ROBUST_SCALE` and ``robust_scale``; ``robust_scale`` until one is known. A
        fixed wide kernel gives nearly full weight to points matched to the wrong surface (a
        few centimetres off, at edges and small objects), whose distances do not vanish at the
        true pose and bias it by millimetres; a kernel set by the sensor's noise does not.
        """
        config = self.config
        if config.robust_sigmas <= 0 or not math.isfinite(self.noise_sigma):
            return config.robust_scale
        scale = config.robust_sigmas * self.noise_sigma
        return min(config.robust_scale, max(scale, _MIN_ROBUST_SCALE))

    def _update_noise(self, points, s, T_b, T_e, planes) -> None:
        """Robust standard deviation (1.4826 median absolute value) of the final distances."""
        from nbcalib.kernels.ct_icp import PLANE_NX, PLANE_NZ, PLANE_OFFSET, PLANE_WEIGHT

        rows = planes[:, PLANE_WEIGHT] > 0
        if self.config.robust_sigmas <= 0 or rows.sum() < self.config.min_correspondences:
            return
        R_b, t_b = np.ascontiguousarray(T_b[:3, :3]), np.ascontiguousarray(T_b[:3, 3])
        phi = _relative_rotation_vector(R_b, T_e[:3, :3])
        world = np.empty_like(points)
        self._deskew(points, s, R_b, t_b, np.ascontiguousarray(T_e[:3, 3]), phi, world)
        normals = planes[rows, PLANE_NX : PLANE_NZ + 1]
        distance = np.einsum("ij,ij->i", normals, world[rows]) - planes[rows, PLANE_OFFSET]
        self.noise_sigma = 1.4826 * float(np.median(np.abs(distance)))

    def _associate_rows(self, points, s, R_b, t_b, t_e, phi, map_args, planes) -> None:
        """Planes of all source points (``ct_icp._associate``), on one or two threads.

        With ``threads == 2`` the rows are split between this thread and a worker (the kernel
        releases the GIL; rows are independent, so the result is the same).
        """
        n = points.shape[0]
        if self._pool is None or n < 2 * _MIN_ROWS_PER_THREAD:
            self._associate(points, s, R_b, t_b, t_e, phi, *map_args, planes)
            return
        half = n // 2
        other = self._pool.submit(
            self._associate, points[half:], s[half:], R_b, t_b, t_e, phi, *map_args, planes[half:]
        )
        self._associate(points[:half], s[:half], R_b, t_b, t_e, phi, *map_args, planes[:half])
        other.result()

    # -- step 4: deskew, accumulate, map -----------------------------------------------------
    def deskewed(self, prepared: _Prepared, T_b: np.ndarray, T_e: np.ndarray) -> np.ndarray:
        """The scan's points beyond min_distance, deskewed into the first scan's frame."""
        from nbcalib.kernels.ct_icp import _deskew, _deskew_parallel

        R_b, t_b = np.ascontiguousarray(T_b[:3, :3]), np.ascontiguousarray(T_b[:3, 3])
        phi = _relative_rotation_vector(R_b, T_e[:3, :3])
        out = np.empty_like(prepared.points)
        kernel = _deskew_parallel if self.config.parallel else _deskew
        kernel(prepared.points, prepared.s, R_b, t_b, np.ascontiguousarray(T_e[:3, 3]), phi, out)
        return out

    def accumulate(self, prepared: _Prepared, points_world: np.ndarray) -> int:
        """Queue the deskewed points for the output voxel grid; returns how many there are.

        With ``background_accumulation`` the de-duplication runs on one worker thread (the
        kernel releases the GIL) while the next scan is registered; scans are folded in strictly
        in order, so the result is the same as in the foreground.
        """
        intensity = prepared.intensity
        if self._worker is None:
            self.output.add(points_world, intensity)
        else:
            if self._pending is not None:
                self._pending.result()  # at most one scan in flight: bounded memory
            self._pending = self._worker.submit(self.output.add, points_world, intensity)
        return int(points_world.shape[0])

    def finish(self) -> tuple[np.ndarray, np.ndarray]:
        """Wait for the queued scans and return the de-duplicated cloud."""
        self.close()
        return self.output.result()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
        if self._worker is not None:
            try:
                if self._pending is not None:
                    self._pending.result()
            finally:
                self._worker.shutdown(wait=True)
                self._worker, self._pending = None, None

    def insert(self, points_world: np.ndarray, sensor_position: np.ndarray) -> None:
        self.map.insert(points_world)
        self.scans_inserted += 1
        if self.scans_inserted % 10 == 0:
            self.map.remove_far(sensor_position, self.config.map_max_distance)

    def reset_map(self) -> None:
        self.map = VoxelMap(
            self.config.map_voxel_size,
            max_points_per_voxel=self.config.map_max_points_per_voxel,
            min_spacing=self.config.map_min_spacing,
        )
        self.scans_inserted = 0


def _solve(H: np.ndarray, g: np.ndarray) -> np.ndarray:
    """Gauss-Newton step ``-H^-1 g``, with a tiny Levenberg damping against a singular ``H``."""
    damping = 1e-9 * max(float(np.trace(H)) / H.shape[0], 1e-12)
    return -np.linalg.solve(H + damping * np.eye(H.shape[0]), g)


def _add_priors(H, g, T_b, T_e, T_b_pred, phi, phi_pred, d_pred, w_begin, config) -> None:
    """Add the begin prior and the intra-scan motion prior to the normal equations, in place.

    Begin: ``e = [t_b - t_pred, log(R_b R_pred^T)]``, Jacobian ~ I on ``[v_b, w_b]``.
    Motion: ``e = [R_b^T (t_e - t_b) - d_pred, log(R_b^T R_e) - phi_pred]`` (body-frame motion
    over the scan), Jacobian to first order in the increments ``R <- exp(w) R, t <- t + v``.
    """
    R_b, t_b, t_e = T_b[:3, :3], T_b[:3, 3], T_e[:3, 3]
    e_begin = np.concatenate(
        [t_b - T_b_pred[:3, 3], _relative_rotation_vector(R_b.T, T_b_pred[:3, :3].T)]
    )
    H[:6, :6] += w_begin * np.eye(6)
    g[:6] += w_begin * e_begin
    w_motion = config.motion_prior_weight
    e_motion = np.concatenate([R_b.T @ (t_e - t_b) - d_pred, phi - phi_pred])
    J = np.zeros((6, 12))
    J[:3, 0:3] = -R_b.T
    J[:3, 3:6] = R_b.T @ _hat(t_e - t_b)
    J[:3, 6:9] = R_b.T
    J[3:, 3:6] = -R_b.T
    J[3:, 9:12] = R_b.T
    H += w_motion * (J.T @ J)
    g += w_motion * (J.T @ e_motion)


def _apply_increment(T: np.ndarray, delta: np.ndarray, so3_exp_kernel) -> np.ndarray:
    """R <- exp(w) R, t <- t + v for delta = [v, w] (the SO(3) x R^3 left increment)."""
    out = T.copy()
    out[:3, :3] = so3_exp_kernel(np.ascontiguousarray(delta[3:])) @ T[:3, :3]
    out[:3, 3] = T[:3, 3] + delta[:3]
    return out


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


def _prepare_dynamic(scan: _Scan, icp: _ContinuousTimeICP) -> _Prepared:
    points, intensity, s, n_finite, duration = _select(scan, icp.config.min_distance, icp.config)
    sub = icp.downsample(points)
    return _Prepared(
        n_in=n_finite,
        points=points,
        intensity=intensity,
        s=s,
        duration=duration,
        registration=np.ascontiguousarray(points[sub]),
        registration_s=np.ascontiguousarray(s[sub]),
    )


def integrate_dynamic(
    scans: Iterable,
    times: Sequence | None = None,
    *,
    config: DynamicIntegrationConfig | None = None,
    progress: bool | ProgressCallback | None = None,
) -> DenseCloud:
    """Motion-compensated accumulation of a moving spinning LiDAR (paper section III-C).

    Continuous-time ICP estimates each scan's begin and end pose against a local voxel map; every
    point is deskewed with the pose interpolated at its time and accumulated in the LiDAR frame at
    the start of the first scan (module docstring).

    Parameters
    ----------
    scans : iterable
        Scans in time order, consecutive (each begins where the previous one ended), as for
        :func:`integrate_static`; objects with ``times`` (N,) provide per-point times.
    times : sequence of (array_like of shape (N_k,) or None), optional
        Per-point times of each scan, seconds (any offset: they are normalised per scan); they
        override a scan's own. A scan with neither gets times synthesised from the azimuth
        (:func:`synthesize_times_from_azimuth` with ``config.frame_rate``).
    config : DynamicIntegrationConfig, optional
        Knobs; defaults as documented there.
    progress : bool or callable, optional
        ``True`` for a progress bar on stderr, or a callback ``(done, total)``.

    Returns
    -------
    DenseCloud
        Points in the LiDAR frame at the start of the first scan, with ``T_first_scanbegin``,
        ``T_first_scanend`` per scan and per-scan registration diagnostics in ``stats``.

    Raises
    ------
    InputError
        No scan, or no finite point beyond ``min_distance`` in any scan.
    ValueError
        ``times`` does not match the scans (count, or length of a scan's times).
    """
    config = DynamicIntegrationConfig() if config is None else config
    if not isinstance(config, DynamicIntegrationConfig):
        raise ValueError(f"config must be a DynamicIntegrationConfig, got {type(config).__name__}")
    icp = _ContinuousTimeICP(config)
    n_scans = len(scans) if hasattr(scans, "__len__") else None
    report = _Progress(progress, n_scans, "integrate")

    try:
        return _integrate_dynamic_loop(scans, times, config, icp, report, n_scans)
    finally:
        icp.close()


def _integrate_dynamic_loop(scans, times, config, icp, report, n_scans) -> DenseCloud:
    """The scan loop of :func:`integrate_dynamic` (steps in the module docstring)."""
    begins: list[np.ndarray] = []
    ends: list[np.ndarray] = []
    stats: dict[str, list] = {
        key: []
        for key in (
            "points_in",
            "points_used",
            "iterations",
            "correspondences",
            "residual_rms",
            "registered",
        )
    }
    previous: tuple[np.ndarray, np.ndarray, float] | None = None  # last registered (Tb, Te, dur)
    end_of_last = np.eye(4)
    pending_first: tuple[int, _Prepared] | None = None  # the first usable scan, not accumulated
    n_registered = 0

    def record(prepared: _Prepared, reg: _Registration, used: int) -> None:
        begins.append(reg.T_begin)
        ends.append(reg.T_end)
        stats["points_in"].append(prepared.n_in)
        stats["points_used"].append(used)
        stats["iterations"].append(reg.iterations)
        stats["correspondences"].append(reg.correspondences)
        stats["residual_rms"].append(reg.residual_rms)
        stats["registered"].append(reg.registered)

    def flush_first() -> None:
        nonlocal pending_first
        if pending_first is not None:
            index, prepared = pending_first
            world = icp.deskewed(prepared, begins[index], ends[index])
            stats["points_used"][index] = icp.accumulate(prepared, world)
            pending_first = None

    for k, raw, scan_times in _iterate_scans(scans, times):
        prepared = _prepare_dynamic(_prepare_scan(raw, scan_times, k), icp)
        if k == 0 and n_scans:  # size the output for all scans at once (no regrowth)
            icp.output.reserve(n_scans * prepared.points.shape[0])
        T_b_pred, T_e_pred, phi_pred, d_pred = icp.predict(previous, end_of_last, prepared.duration)

        if prepared.registration.shape[0] == 0:
            # empty (or everything within min_distance): keep the prediction, accumulate nothing
            record(prepared, _Registration(T_b_pred, T_e_pred, 0, 0, math.nan, False), 0)
        elif pending_first is None and n_registered == 0:
            # the first scan defines the frame: begin = end = identity until the second scan
            # is registered; its accumulation waits for its end pose
            reg = _Registration(np.eye(4), np.eye(4), 0, 0, 0.0, True)
            icp.insert(icp.deskewed(prepared, reg.T_begin, reg.T_end), np.zeros(3))
            pending_first = (len(begins), prepared)
            record(prepared, reg, 0)
            previous = (reg.T_begin, reg.T_end, prepared.duration)
            end_of_last = reg.T_end
            n_registered = 1
        else:
            src, src_s = prepared.registration, prepared.registration_s
            # a wide robust kernel first while the velocity is still unknown
            early = n_registered < _ANNEALED_SCANS
            reg = icp.register(src, src_s, T_b_pred, T_e_pred, phi_pred, d_pred, anneal=early)
            if pending_first is not None:
                reg = _refine_first(icp, pending_first, src, src_s, reg, ends)
                flush_first()
            world = icp.deskewed(prepared, reg.T_begin, reg.T_end)
            used = icp.accumulate(prepared, world)
            if reg.registered:
                icp.insert(world, reg.T_end[:3, 3])
                previous = (reg.T_begin, reg.T_end, prepared.duration)
                n_registered += 1
            end_of_last = reg.T_end
            record(prepared, reg, used)
        report(k + 1)
    report.close()

    if not begins:
        raise InputError("no scans to integrate")
    if n_registered == 0:
        raise InputError(
            f"no finite point at a range of at least min_distance={config.min_distance} m in "
            f"{len(begins)} scan(s)"
        )
    flush_first()  # a single usable scan: accumulate it as it is
    points, intensity = icp.finish()
    return DenseCloud(
        points=points,
        intensity=intensity,
        T_first_scanbegin=np.stack(begins),
        T_first_scanend=np.stack(ends),
        stats={key: np.array(value) for key, value in stats.items()},
    )


def _motion_size(T: np.ndarray) -> tuple[float, float]:
    """Translation (m) and rotation angle (deg) of a rigid transform."""
    angle = np.linalg.norm(_relative_rotation_vector(np.eye(3), T[:3, :3]))
    return float(np.linalg.norm(T[:3, 3])), float(np.degrees(angle))


def _refine_first(icp, pending_first, src, src_s, reg, ends) -> _Registration:
    """Give a moving first scan its end pose, rebuild the map, register the second scan again.

    A first scan inserted into the map without deskewing distorts it, and the second scan,
    registered against it, inherits the distortion. At constant velocity, though, two
    consecutive raw scans are distorted alike, so the *rigid* transform between them is the
    motion over one scan (the insight of kiss-icp's deskewing): the second scan is aligned
    rigidly (all its points at ``s = 0``) to the raw first one, which gives the first scan's end
    pose and a constant-velocity prediction for the second; below 1 cm and 0.1 degree the first
    scan is taken to be at rest and nothing changes. Otherwise, up to
    ``_REFINE_FIRST_ROUNDS`` times: deskew the first scan, rebuild the map, register the second
    (continuity prior relaxed, since its centre is what is being estimated), until its begin pose
    moves by less than a millimetre.

    Constant velocity is an assumption, and the collection procedure breaks it: the sensor
    rests, then starts moving, so the first scan is still while the second accelerates, and the
    rigid alignment then reports part of the second scan's motion as the first's; the first
    scan, deskewed with it, went into the map distorted and every later scan inherited the
    offset (the nodding benchmark's drift, ``docs/BENCHMARKS.md``). So the data decides: the
    second scan is registered by continuous-time ICP against the raw first scan with no prior on
    its begin pose. At constant velocity the two raw scans are distorted alike and it begins at
    ``T_01``; after a first scan at rest it begins near the identity. The first scan counts as
    moving only when that begin pose is at least ``1 / _MOVING_FIRST_RATIO`` times closer to
    ``T_01`` than to the identity (translation plus rotation at the median range).
    """
    index, prepared = pending_first
    if not (reg.registered and icp.config.refine_first_scan):
        return reg
    relaxed = _REFINE_BEGIN_PRIOR_SCALE * icp.config.begin_prior_weight
    zero = np.zeros(3)
    rigid = icp.register(
        src,
        np.zeros_like(src_s),
        np.eye(4),
        np.eye(4),
        zero,
        zero,
        begin_prior_weight=_BOOTSTRAP_PRIOR_SCALE * icp.config.begin_prior_weight,
        anneal=True,
    )
    if not rigid.registered:
        return reg
    T_01 = rigid.T_begin  # the motion over one scan, if the velocity was constant
    moved_m, turned_deg = _motion_size(T_01)
    if moved_m < _REST_TRANSLATION and turned_deg < _REST_ROTATION_DEG:
        return reg  # the first scan was taken at rest (as the collection procedure asks)
    # where does the second scan begin, by its own data alone (no begin prior), against the raw
    # first scan? At constant velocity the raw scans are distorted alike and it begins at T_01;
    # after a first scan at rest it begins at the identity (and accelerates within the scan)
    free = icp.register(
        src, src_s, reg.T_begin, reg.T_end, zero, zero, begin_prior_weight=0.0, anneal=True
    )
    reach = float(np.sqrt(np.median(np.einsum("ij,ij->i", src, src))))
    if not free.registered:
        return reg
    to_rest = _pose_distance(free.T_begin, np.eye(4), reach)
    to_moving = _pose_distance(free.T_begin, T_01, reach)
    if to_moving > _MOVING_FIRST_RATIO * to_rest:
        return reg  # not clearly moving: keep the first scan at rest
    guess = _Registration(T_01, T_01 @ T_01, 0, 0, math.nan, True)
    for _ in range(_REFINE_FIRST_ROUNDS):
        _rebuild_first(icp, prepared, ends, index, guess.T_begin)
        R_b = guess.T_begin[:3, :3]
        phi = _relative_rotation_vector(R_b, guess.T_end[:3, :3])
        d = R_b.T @ (guess.T_end[:3, 3] - guess.T_begin[:3, 3])
        again = icp.register(
            src, src_s, guess.T_begin, guess.T_end, phi, d, begin_prior_weight=relaxed, anneal=True
        )
        if not again.registered:
            break
        change = np.abs(again.T_begin - guess.T_begin).max()
        guess = again
        if change < 1e-3:
            break
    if guess.registered and guess.iterations > 0:
        return guess
    _rebuild_first(icp, prepared, ends, index, np.eye(4))  # back to the raw first scan
    return reg


def _pose_distance(T_a: np.ndarray, T_b: np.ndarray, reach: float) -> float:
    """Translation plus rotation angle times ``reach`` between two poses, metres."""
    angle = np.linalg.norm(_relative_rotation_vector(T_a[:3, :3], T_b[:3, :3]))
    return float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]) + reach * angle)


def _rebuild_first(icp, prepared, ends, index, T_end) -> None:
    """Set the first scan's end pose and rebuild the map from it deskewed with that pose."""
    ends[index] = T_end.copy()
    icp.reset_map()
    icp.insert(icp.deskewed(prepared, np.eye(4), ends[index]), np.zeros(3))


#: the first scan counts as moving when the second begins this much closer to T_01 than to rest
_MOVING_FIRST_RATIO = 0.5
#: smallest Geman-McClure scale of the adaptive kernel, metres
_MIN_ROBUST_SCALE = 0.01
#: the first scans (and the bootstrap of the first) start with a wide robust kernel
_ANNEALED_SCANS = 3
#: below this many source points per thread, the plane lookup stays on one thread
_MIN_ROWS_PER_THREAD = 500
#: at most this many rounds of :func:`_refine_first`
_REFINE_FIRST_ROUNDS = 3
#: continuity prior in those rounds, relative to ``begin_prior_weight``
_REFINE_BEGIN_PRIOR_SCALE = 0.1
#: below this motion over the first scan (metres, degrees), it was taken at rest
_REST_TRANSLATION = 0.01
_REST_ROTATION_DEG = 0.1
#: prior of the rigid bootstrap at no motion, relative to ``begin_prior_weight``
_BOOTSTRAP_PRIOR_SCALE = 0.01


# ---------------------------------------------------------------------------------------------
# Sharpness of a cloud
# ---------------------------------------------------------------------------------------------


def local_thickness(
    points: Any,
    *,
    k: int = 20,
    max_distance: float = 0.3,
    n_samples: int = 20000,
    min_planarity: float = 0.5,
    direction: Any = None,
    min_alignment: float = 0.7,
    seed: int = 0,
) -> float:
    """Median local thickness of a cloud: how blurred its surfaces are.

    For ``n_samples`` points drawn at random (with ``seed``), the ``k`` nearest points within
    ``max_distance`` are fitted with a plane by PCA; the thickness is the standard deviation
    along the normal, ``sqrt(l0)`` of the smallest eigenvalue. Only planar neighbourhoods count
    (CT-ICP planarity ``(sqrt(l1) - sqrt(l0)) / sqrt(l2) >= min_planarity``, so edges and
    vegetation do not dominate). Motion blur of an accumulated cloud thickens its surfaces, so a
    better-deskewed cloud has a smaller value. A motion blurs only the surfaces it moves along
    their normal (driving forward smears walls facing the car, not the road nor the facades
    along it): ``direction`` keeps the surfaces whose normal is within ``acos(min_alignment)``
    of it.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        The cloud, metres.
    k : int
        Neighbours per sample.
    max_distance : float
        Neighbour radius, metres.
    n_samples : int
        Number of sample points.
    min_planarity : float
        Planarity a sample neighbourhood needs to count.
    direction : array_like of shape (3,), optional
        Keep only surfaces whose unit normal ``n`` has ``|n . direction| >= min_alignment``
        (``direction`` is normalised).
    min_alignment : float
        See ``direction``.
    seed : int
        Seed of the sampling.

    Returns
    -------
    float
        Median thickness, metres (NaN if no neighbourhood qualifies).
    """
    from scipy.spatial import cKDTree

    points = _points_arg(points, "points")
    rng = np.random.default_rng(seed)
    n = points.shape[0]
    if n == 0:
        return math.nan
    samples = rng.choice(n, size=min(n_samples, n), replace=False)
    tree = cKDTree(points)
    d, idx = tree.query(points[samples], k=k, distance_upper_bound=max_distance)
    full = np.isfinite(d).all(axis=1)
    if not full.any():
        return math.nan
    nb = points[idx[full]]  # (M, k, 3)
    centred = nb - nb.mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", centred, centred) / k
    eig, vec = np.linalg.eigh(cov)  # ascending
    eig = np.clip(eig, 0.0, None)
    planarity = (np.sqrt(eig[:, 1]) - np.sqrt(eig[:, 0])) / np.sqrt(np.maximum(eig[:, 2], 1e-30))
    good = planarity >= min_planarity
    if direction is not None:
        u = np.asarray(direction, dtype=np.float64)
        u = u / np.linalg.norm(u)
        good &= np.abs(vec[:, :, 0] @ u) >= min_alignment
    if not good.any():
        return math.nan
    return float(np.median(np.sqrt(eig[good, 0])))
