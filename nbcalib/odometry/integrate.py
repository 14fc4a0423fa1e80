"""Dense clouds from a moving spinning LiDAR: LiDAR odometry by continuous-time ICP (paper III-C).

A single LiDAR scan is too sparse to render a useful intensity image, so the method accumulates
several seconds of scans into one dense cloud, expressed in the LiDAR frame at the start of the
first scan (the frame the camera image pairs with). A spinning LiDAR (Velodyne, Ouster) must
move, by hand or on a vehicle, to fill the gaps between its rings: :func:`integrate_dynamic`
estimates by continuous-time ICP, for each scan, the pose at its first and at its last point;
each point is then moved with the pose interpolated at its own time (deskewing) into the frame of
the first scan, and accumulated on a fine voxel grid. (A LiDAR at rest needs none of this:
:func:`nbcalib.preprocess.accumulate.integrate_static`.)

Continuous-time ICP, step by step for scan ``k``
(:class:`~nbcalib.odometry.config.DynamicIntegrationConfig` holds the knobs,
:mod:`nbcalib.odometry.ct_icp` the registration):

1. **Predict** the begin and end poses at constant velocity: the scan begins where the previous
   one ended and moves as the previous one did (same body-frame rotation and translation,
   scaled by the ratio of the scan durations).
2. **Downsample** the scan for registration to about ``registration_points`` points spread over
   ``registration_voxel_size`` voxels (:func:`~nbcalib.odometry.voxelmap.stratified_downsample`).
3. **Register** against the local map, an iVox-like voxel hash with a linear container of points
   per voxel (:class:`~nbcalib.odometry.voxelmap.VoxelMap`): Gauss-Newton on the 12 parameters
   of the two poses, with the point-to-plane residuals of :mod:`nbcalib.kernels.ct_icp` (plane
   of the ``knn`` nearest map points, CT-ICP planarity weight, thickness gate, Geman-McClure
   robust kernel), a strong prior that the scan begins where the previous one ended
   (continuity), and a weak prior on the intra-scan motion (see ``motion_prior``). Planes are
   looked up again only when the points have moved (``reassociation_distance``).
4. **Deskew** the full-resolution scan with the final poses (:mod:`nbcalib.odometry.deskew`),
   accumulate it on the output voxel grid, and insert it into the map (which forgets voxels
   beyond ``map_max_distance``).

The first scan defines the output frame: its begin pose is the identity. Its end pose is taken as
the begin pose of the second scan, bootstrapped by a rigid alignment of the two raw scans (equal
to the motion over one scan at constant velocity) when the second scan's own registration says
the first one was moving, and the identity (at rest) otherwise; the map is then rebuilt from the
first scan deskewed with it and the second scan is registered again (``refine_first_scan``).

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
- the robust kernel narrows to the sensor's noise once a scan has converged
  (``robust_sigmas``, :mod:`nbcalib.odometry.ct_icp`);
- a moving first scan is deskewed (the reference assumes the rig at rest at the start);
- constant-velocity prediction at full rate (the reference extrapolates 0.75 of the last motion);
- ``min_distance`` is the range from the sensor when the point was taken (the reference measures
  it from the origin of the first scan, which keeps the vehicle's own returns after it moved);
- the output is ordered by first appearance of each voxel, not in hash-map order, so the same
  input always gives the same ``.ply`` and index map; voxel values are averaged by default.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError
from nbcalib.odometry.config import (
    DEFAULT_FRAME_RATE,
    DEFAULT_MIN_DISTANCE,
    DEFAULT_VOXEL_SIZE,
    DynamicIntegrationConfig,
)
from nbcalib.odometry.ct_icp import _ContinuousTimeICP, _pose_distance, _Registration
from nbcalib.odometry.deskew import _relative_rotation_vector
from nbcalib.odometry.scans import (
    ProgressCallback,
    _check_min_distance,
    _iterate_scans,
    _prepare_scan,
    _Prepared,
    _Progress,
    _Scan,
    _select,
)
from nbcalib.odometry.voxelmap import _check_voxel

if TYPE_CHECKING:  # the result type; imported where it is built (preprocess imports odometry)
    from nbcalib.preprocess.accumulate import DenseCloud

__all__ = ["integrate_dynamic"]

#: the first scan counts as moving when the second begins this much closer to T_01 than to rest
_MOVING_FIRST_RATIO = 0.5
#: the first scans (and the bootstrap of the first) start with a wide robust kernel
_ANNEALED_SCANS = 3
#: at most this many rounds of :func:`_refine_first`
_REFINE_FIRST_ROUNDS = 3
#: continuity prior in those rounds, relative to ``begin_prior_weight``
_REFINE_BEGIN_PRIOR_SCALE = 0.1
#: below this motion over the first scan (metres, degrees), it was taken at rest
_REST_TRANSLATION = 0.01
_REST_ROTATION_DEG = 0.1
#: prior of the rigid bootstrap at no motion, relative to ``begin_prior_weight``
_BOOTSTRAP_PRIOR_SCALE = 0.01


def _prepare_dynamic(
    scan: _Scan, icp: _ContinuousTimeICP, min_distance: float, sweep: tuple[float, bool, float]
) -> _Prepared:
    points, intensity, s, n_finite, duration = _select(scan, min_distance, sweep)
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
    voxel_size: float = DEFAULT_VOXEL_SIZE,
    min_distance: float = DEFAULT_MIN_DISTANCE,
    frame_rate: float = DEFAULT_FRAME_RATE,
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
        :func:`~nbcalib.preprocess.accumulate.integrate_static`; objects with ``times`` (N,)
        provide per-point times.
    times : sequence of (array_like of shape (N_k,) or None), optional
        Per-point times of each scan, seconds (any offset: they are normalised per scan); they
        override a scan's own. A scan with neither gets times synthesised from the azimuth
        (:func:`~nbcalib.odometry.scans.synthesize_times_from_azimuth` with ``frame_rate``).
    config : DynamicIntegrationConfig, optional
        Knobs of continuous-time ICP; defaults as documented there.
    voxel_size : float
        Output voxel, metres (:data:`~nbcalib.odometry.config.DEFAULT_VOXEL_SIZE`: 0.002, as the
        reference CLI).
    min_distance : float
        Points closer than this to the sensor are dropped, metres.
    frame_rate : float
        Scans per second, Hz; only used to synthesise per-point times from the azimuth when a
        scan carries none.
    progress : bool or callable, optional
        ``True`` for a progress display (:class:`nbcalib.progress.Progress`: a bar on a
        terminal, step lines in a log, nothing when the ``nbcalib`` logger is quiet), or a
        callback ``(done, total)``.

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
        ``times`` does not match the scans (count, or length of a scan's times), or a
        setting is out of range.
    """
    config = DynamicIntegrationConfig() if config is None else config
    if not isinstance(config, DynamicIntegrationConfig):
        raise ValueError(f"config must be a DynamicIntegrationConfig, got {type(config).__name__}")
    _check_voxel(voxel_size)
    _check_min_distance(min_distance)
    if not (np.isfinite(frame_rate) and frame_rate > 0):
        raise ValueError(f"frame_rate must be a positive number, got {frame_rate!r}")
    sweep = (frame_rate, config.clockwise, config.start_azimuth_deg)
    icp = _ContinuousTimeICP(config, voxel_size=voxel_size)
    n_scans = len(scans) if hasattr(scans, "__len__") else None
    report = _Progress(progress, n_scans, "integrate")

    try:
        return _integrate_dynamic_loop(scans, times, icp, report, n_scans, min_distance, sweep)
    except BaseException:
        report.close(failed=True)  # end a bar's line; the loop closes it on success
        raise
    finally:
        icp.close()


def _integrate_dynamic_loop(scans, times, icp, report, n_scans, min_distance, sweep) -> DenseCloud:
    """The scan loop of :func:`integrate_dynamic` (steps in the module docstring)."""
    from nbcalib.preprocess.accumulate import DenseCloud

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
        prepared = _prepare_dynamic(_prepare_scan(raw, scan_times, k), icp, min_distance, sweep)
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
            f"no finite point at a range of at least min_distance={min_distance} m in "
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


def _rebuild_first(icp, prepared, ends, index, T_end) -> None:
    """Set the first scan's end pose and rebuild the map from it deskewed with that pose."""
    ends[index] = T_end.copy()
    icp.reset_map()
    icp.insert(icp.deskewed(prepared, np.eye(4), ends[index]), np.zeros(3))
