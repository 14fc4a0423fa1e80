"""LiDAR odometry for dense clouds: continuous-time ICP and deskewing (paper section III-C).

A spinning LiDAR that moves while it scans is registered scan by scan against a local map, and
every point is moved with the pose at its own time into the LiDAR frame at the start of the
first scan. Modules, in the order of the method (:mod:`nbcalib.odometry.integrate` tells it step
by step):

- :mod:`nbcalib.odometry.config`: :class:`DynamicIntegrationConfig` (the CT-ICP knobs) and the
  defaults shared with the preprocessing stage (output voxel, minimum range, frame rate);
- :mod:`nbcalib.odometry.scans`: input checks, per-point times, the points of a scan used;
- :mod:`nbcalib.odometry.voxelmap`: downsampling, voxel de-duplication, the local voxel map;
- :mod:`nbcalib.odometry.deskew`: each point moved with its interpolated pose;
- :mod:`nbcalib.odometry.ct_icp`: the registration of one scan (priors, Gauss-Newton);
- :mod:`nbcalib.odometry.integrate`: :func:`integrate_dynamic`, the scan loop and the first
  scan's refinement;
- :mod:`nbcalib.odometry.sharpness`: :func:`local_thickness`, how blurred a cloud's surfaces are.

The numba kernels are in :mod:`nbcalib.kernels.voxelmap` and :mod:`nbcalib.kernels.ct_icp`,
their slow references in :mod:`nbcalib.reference.integrate`. Static accumulation (a LiDAR at
rest) and the :class:`~nbcalib.preprocess.accumulate.DenseCloud` result are in
:mod:`nbcalib.preprocess.accumulate`.
"""

from __future__ import annotations

from nbcalib.odometry.config import (
    DEDUP_RULES,
    DEFAULT_FRAME_RATE,
    DEFAULT_MIN_DISTANCE,
    DEFAULT_VOXEL_SIZE,
    DynamicIntegrationConfig,
)
from nbcalib.odometry.deskew import deskew
from nbcalib.odometry.integrate import integrate_dynamic
from nbcalib.odometry.scans import normalized_scan_times, synthesize_times_from_azimuth
from nbcalib.odometry.sharpness import local_thickness
from nbcalib.odometry.voxelmap import (
    VoxelMap,
    stratified_downsample,
    voxel_deduplicate,
    voxel_downsample,
)

__all__ = [
    "DEDUP_RULES",
    "DEFAULT_FRAME_RATE",
    "DEFAULT_MIN_DISTANCE",
    "DEFAULT_VOXEL_SIZE",
    "DynamicIntegrationConfig",
    "VoxelMap",
    "deskew",
    "integrate_dynamic",
    "local_thickness",
    "normalized_scan_times",
    "stratified_downsample",
    "synthesize_times_from_azimuth",
    "voxel_deduplicate",
    "voxel_downsample",
]
