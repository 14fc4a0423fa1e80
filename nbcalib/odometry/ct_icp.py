"""Scan-to-map continuous-time ICP: the registration of one scan (steps 1-4 of the method).

The knobs are :class:`~nbcalib.odometry.config.DynamicIntegrationConfig`; the scan loop that
drives it, and the method step by step, are in :mod:`nbcalib.odometry.integrate`. For scan ``k``:
predict its begin and end poses at constant velocity (:meth:`_ContinuousTimeICP.predict`),
downsample it, register it against the local :class:`~nbcalib.odometry.voxelmap.VoxelMap` by
Gauss-Newton on the 12 parameters of the two poses (:meth:`_ContinuousTimeICP.register`:
point-to-plane residuals of :mod:`nbcalib.kernels.ct_icp`, a continuity prior on the begin pose
and a weak prior on the intra-scan motion), then deskew it, accumulate it and insert it into the
map.

The robust kernel narrows to the noise: once a scan has converged with the kernel of scale
``robust_scale`` (and moved as predicted), the planes are looked up again with a scale of
``robust_sigmas`` times the noise of the point-to-plane distances of the previous scan. Points
matched to the wrong surface (a few centimetres off at edges and small objects) do not vanish at
the true pose; with a 10 cm kernel they biased every scan by millimetres, the same way at rest
as in motion.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nbcalib.odometry.config import DynamicIntegrationConfig
from nbcalib.odometry.deskew import _relative_rotation_vector
from nbcalib.odometry.scans import _Prepared
from nbcalib.odometry.voxelmap import VoxelMap, _VoxelAccumulator, stratified_downsample

__all__: list[str] = []  # private machinery of nbcalib.odometry.integrate.integrate_dynamic

#: smallest Geman-McClure scale of the adaptive kernel, metres
_MIN_ROBUST_SCALE = 0.01
#: below this many source points per thread, the plane lookup stays on one thread
_MIN_ROWS_PER_THREAD = 500


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
    """Scan-to-map continuous-time ICP and the accumulation it feeds (module docstring).

    Parameters
    ----------
    config : DynamicIntegrationConfig
        The knobs.
    voxel_size : float
        Output voxel of the accumulated cloud, metres.
    """

    def __init__(self, config: DynamicIntegrationConfig, *, voxel_size: float):
        from nbcalib.kernels import ct_icp

        self.config = config
        self.map = VoxelMap(
            config.map_voxel_size,
            max_points_per_voxel=config.map_max_points_per_voxel,
            min_spacing=config.map_min_spacing,
        )
        self.output = _VoxelAccumulator(voxel_size, config.dedup)
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


def _pose_distance(T_a: np.ndarray, T_b: np.ndarray, reach: float) -> float:
    """Translation plus rotation angle times ``reach`` between two poses, metres."""
    angle = np.linalg.norm(_relative_rotation_vector(T_a[:3, :3], T_b[:3, :3]))
    return float(np.linalg.norm(T_a[:3, 3] - T_b[:3, 3]) + reach * angle)
