"""Settings of the LiDAR odometry: the continuous-time ICP knobs and the shared defaults.

The output voxel, the minimum range and the frame rate are settings of the preprocessing stage
as a whole (static accumulation uses the first two too): their defaults are defined here, once,
and :func:`~nbcalib.odometry.integrate.integrate_dynamic` and
:func:`~nbcalib.preprocess.accumulate.integrate_static` take them as keyword arguments.
:class:`DynamicIntegrationConfig` holds only what continuous-time ICP adds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "DEDUP_RULES",
    "DEFAULT_FRAME_RATE",
    "DEFAULT_MIN_DISTANCE",
    "DEFAULT_VOXEL_SIZE",
    "DynamicIntegrationConfig",
]

#: Voxel de-duplication rules: ``"mean"`` (default) or ``"last"`` (the reference's overwrite).
DEDUP_RULES = ("mean", "last")

#: Default output voxel, metres: the reference CLI's ``--voxel_resolution`` (its parameter
#: structs say 0.05 m, but the command line overrides them with 0.002 m).
DEFAULT_VOXEL_SIZE = 0.002
#: Default minimum range, metres (the reference CLI's ``--min_distance``).
DEFAULT_MIN_DISTANCE = 1.0
#: Default scan rate, Hz: only used to synthesise per-point times from the azimuth for scans that
#: carry none (Velodyne, Ouster and KITTI spin at 10 Hz).
DEFAULT_FRAME_RATE = 10.0


@dataclass(frozen=True)
class DynamicIntegrationConfig:
    """Knobs of :func:`~nbcalib.odometry.integrate.integrate_dynamic` (continuous-time ICP).

    The output voxel, the minimum range and the frame rate are arguments of ``integrate_dynamic``
    itself (defaults :data:`DEFAULT_VOXEL_SIZE`, :data:`DEFAULT_MIN_DISTANCE`,
    :data:`DEFAULT_FRAME_RATE`), shared with static accumulation.

    Parameters
    ----------
    dedup : str
        Output voxel rule, ``"mean"`` or ``"last"``
        (:func:`~nbcalib.odometry.voxelmap.voxel_deduplicate`).
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

    dedup: str = "mean"
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
        non_negative = ("map_min_spacing", "begin_prior_weight", "robust_sigmas")
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
