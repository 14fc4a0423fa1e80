"""Rotation-only RANSAC over 2D-3D correspondences (paper section III-D, Algorithm 1).

Each hypothesis is the rotation that aligns the LiDAR bearings of two correspondences with their
camera bearings (Kabsch / Umeyama); its support is the number of correspondences whose LiDAR
bearing, rotated and projected through the real camera model, lands within ``threshold`` pixels
of the keypoint. Translation is ignored (far-field assumption); the Levenberg-Marquardt step
(:mod:`nbcalib.initial_guess.lm`) recovers it.

Differences from the reference toolbox (reference_toolbox.md sections 1.4 and 5):

- ``iterations`` and ``threshold`` are honoured (the reference ignores its command-line values and
  always runs 8192 iterations with a 5 px threshold);
- camera bearings come from :meth:`nbcalib.camera.CameraModel.unproject` (closed form or Newton),
  not a 2-D Nelder-Mead search per keypoint;
- the two correspondences of a hypothesis are distinct (the reference draws with replacement);
- the result is the same for a given seed whatever the number of threads (counter-based random
  streams and an index-based tie rule, see :mod:`nbcalib.kernels.ransac`).
"""

from __future__ import annotations

import operator
from dataclasses import dataclass, field

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.kernels import ransac as _k

__all__ = ["RotationRansacResult", "estimate_rotation_ransac", "usable_correspondences"]

_UINT64_MAX = 2**64 - 1


@dataclass(frozen=True)
class RotationRansacResult:
    """The winning hypothesis of :func:`estimate_rotation_ransac`.

    Attributes
    ----------
    R_camera_lidar : ndarray of shape (3, 3), float64
        Rotation with ``d_camera ~ R_camera_lidar @ d_lidar``.
    inliers : ndarray of shape (M,), bool
        Correspondences the rotation projects within ``threshold`` pixels (unusable ones False).
    best_iteration : int
        Iteration that produced the rotation (the first with the most inliers).
    iterations : int
        Hypotheses evaluated.
    threshold : float
        Inlier threshold, pixels.
    seed : int
        Seed of the random streams.
    usable : ndarray of shape (M,), bool
        Correspondences that took part: a valid camera bearing and a non-zero 3-D point.
    counts : ndarray of shape (iterations,), int64
        Inlier count of every hypothesis.
    """

    R_camera_lidar: np.ndarray
    inliers: np.ndarray
    best_iteration: int
    iterations: int
    threshold: float
    seed: int
    usable: np.ndarray
    counts: np.ndarray
    _bearings: tuple[np.ndarray, np.ndarray] = field(repr=False, compare=False)
    _camera: tuple = field(repr=False, compare=False)

    @property
    def n_inliers(self) -> int:
        """Number of inliers of the winning rotation."""
        return int(np.count_nonzero(self.inliers))

    def rotation_of(self, iteration: int) -> np.ndarray:
        """The rotation hypothesis of iteration ``iteration``, (3, 3) float64."""
        iteration = operator.index(iteration)
        if not 0 <= iteration < self.iterations:
            raise ValueError(f"iteration must be in [0, {self.iterations}), got {iteration}")
        bc, bl = self._bearings
        return _k._rotation_of_iteration(bc, bl, np.uint64(self.seed), iteration)

    def inlier_mask(self, R_camera_lidar) -> np.ndarray:
        """Inliers of any rotation under this result's threshold, shape (M,) bool."""
        R = np.ascontiguousarray(R_camera_lidar, dtype=np.float64)
        if R.shape != (3, 3):
            raise ValueError(f"R_camera_lidar must have shape (3, 3), got {R.shape}")
        bl = self._bearings[1]
        mask = np.zeros(len(bl), dtype=np.bool_)
        model_id, params, uv = self._camera
        _k._inlier_mask(model_id, params, R, bl, uv, self.threshold * self.threshold, mask)
        out = np.zeros(len(self.usable), dtype=bool)
        out[self.usable] = mask
        return out

    def ranked_hypotheses(
        self,
        max_count: int,
        *,
        min_separation_deg: float = 1.0,
        min_inliers: int = 2,
        away_from=None,
        away_deg: float = 0.0,
    ) -> list[tuple[int, int, np.ndarray]]:
        """The best hypotheses with distinct rotations, best first.

        Hypotheses are taken by decreasing inlier count (lower iteration first on ties); one
        within ``min_separation_deg`` of a rotation already taken is skipped, and so is one
        within ``away_deg`` of the rotation ``away_from`` (when given).

        Parameters
        ----------
        max_count : int
            At most this many hypotheses.
        min_separation_deg : float, optional
            Smallest angle between two returned rotations, degrees.
        min_inliers : int, optional
            Hypotheses with fewer inliers are not returned.
        away_from : array_like of shape (3, 3), optional
            A rotation whose neighbourhood is left out (e.g. the answer, to find the best
            *other* one).
        away_deg : float, optional
            Radius of that neighbourhood, degrees.

        Returns
        -------
        list of (iteration, n_inliers, R_camera_lidar)
            The first entry is the RANSAC winner (:attr:`best_iteration`).
        """
        order = np.lexsort((np.arange(self.iterations), -self.counts))
        cos_min = np.cos(np.radians(min_separation_deg))
        cos_away = np.cos(np.radians(away_deg))
        taken: list[tuple[int, int, np.ndarray]] = []
        for i in order:
            count = int(self.counts[i])
            if len(taken) >= max_count or count < min_inliers:
                break
            R = self.rotation_of(int(i))
            # cos of the angle between two rotations: (trace(R1^T R2) - 1) / 2
            if away_from is not None and (np.sum(R * away_from) - 1.0) / 2.0 >= cos_away:
                continue
            if all((np.sum(R * R_t) - 1.0) / 2.0 < cos_min for _, _, R_t in taken):
                taken.append((int(i), count, R))
        return taken


def _check_correspondences(uv_camera, points_lidar) -> tuple[np.ndarray, np.ndarray]:
    uv = np.ascontiguousarray(uv_camera, dtype=np.float64)
    points = np.ascontiguousarray(points_lidar, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv_camera must have shape (M, 2), got {uv.shape}")
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_lidar must have shape (M, 3), got {points.shape}")
    if uv.shape[0] != points.shape[0]:
        raise ValueError(
            f"uv_camera and points_lidar differ in length: {uv.shape[0]} and {points.shape[0]}"
        )
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(points))):
        raise ValueError("uv_camera and points_lidar must be finite")
    return uv, points


def usable_correspondences(
    camera: CameraModel, uv_camera, points_lidar
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bearings of the correspondences and which of them can take part in RANSAC.

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    uv_camera : array_like of shape (M, 2)
        Camera keypoints, pixels (u = column, v = row).
    points_lidar : array_like of shape (M, 3)
        Their 3-D points in the LiDAR frame, metres.

    Returns
    -------
    bearings_camera : ndarray of shape (M, 3), float64
        Unit bearings of the keypoints in the camera frame (NaN outside the model's domain).
    bearings_lidar : ndarray of shape (M, 3), float64
        Unit bearings of the points in the LiDAR frame (NaN for the origin).
    usable : ndarray of shape (M,), bool
        Both bearings valid.
    """
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    uv, points = _check_correspondences(uv_camera, points_lidar)
    bearings_camera = camera.unproject(uv) if len(uv) else np.empty((0, 3))
    norms = np.linalg.norm(points, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        bearings_lidar = points / norms[:, None]
    usable = np.all(np.isfinite(bearings_camera), axis=1) & (norms > 0.0)
    bearings_lidar[~usable] = np.nan
    return bearings_camera, bearings_lidar, usable


def estimate_rotation_ransac(
    camera: CameraModel,
    uv_camera,
    points_lidar,
    *,
    iterations: int = 8192,
    threshold: float = 5.0,
    seed: int = 0,
    parallel: bool = True,
) -> RotationRansacResult:
    """Rotation-only RANSAC (paper Algorithm 1). Wraps ``kernels.ransac._hypothesis_counts``.

    Parameters
    ----------
    camera : CameraModel
        The real camera (projection used for the inlier test).
    uv_camera : array_like of shape (M, 2)
        Camera keypoints, pixels.
    points_lidar : array_like of shape (M, 3)
        Their 3-D points in the LiDAR frame, metres.
    iterations : int, optional
        Number of hypotheses (each from 2 distinct correspondences).
    threshold : float, optional
        Inlier threshold on the reprojection error, pixels.
    seed : int, optional
        Seed in [0, 2**64); the same seed gives the same result on any number of threads.
    parallel : bool, optional
        Evaluate blocks of hypotheses in parallel (same result as serial).

    Returns
    -------
    RotationRansacResult

    Raises
    ------
    InputError
        Fewer than 2 usable correspondences.
    ValueError
        Bad shapes, non-finite values or parameters.
    """
    iterations = operator.index(iterations)
    seed = operator.index(seed)
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    if not (np.isfinite(threshold) and threshold > 0.0):
        raise ValueError(f"threshold must be a finite number > 0 pixels, got {threshold}")
    if not 0 <= seed <= _UINT64_MAX:
        raise ValueError(f"seed must be in [0, 2**64), got {seed}")
    uv, _ = _check_correspondences(uv_camera, points_lidar)
    bearings_camera, bearings_lidar, usable = usable_correspondences(camera, uv, points_lidar)
    n_usable = int(np.count_nonzero(usable))
    if n_usable < 2:
        raise InputError(
            f"too few correspondences for RANSAC: {n_usable} usable of {len(uv)}, need at least 2"
        )
    bc = np.ascontiguousarray(bearings_camera[usable])
    bl = np.ascontiguousarray(bearings_lidar[usable])
    uv_usable = np.ascontiguousarray(uv[usable])
    threshold2 = float(threshold) * float(threshold)
    key = np.uint64(seed)
    kernel = _k._hypothesis_counts_parallel if parallel else _k._hypothesis_counts
    counts = np.empty(iterations, dtype=np.int64)
    kernel(camera.model_id, camera.params, bc, bl, uv_usable, threshold2, key, counts)
    best_iteration = int(np.argmax(counts))  # the first maximum: lowest iteration wins a tie
    R = _k._rotation_of_iteration(bc, bl, key, best_iteration)
    mask = np.zeros(n_usable, dtype=np.bool_)
    _k._inlier_mask(camera.model_id, camera.params, R, bl, uv_usable, threshold2, mask)
    inliers = np.zeros(len(uv), dtype=bool)
    inliers[usable] = mask
    return RotationRansacResult(
        R_camera_lidar=R,
        inliers=inliers,
        best_iteration=int(best_iteration),
        iterations=iterations,
        threshold=float(threshold),
        seed=seed,
        usable=usable,
        counts=counts,
        _bearings=(bc, bl),
        _camera=(camera.model_id, camera.params, uv_usable),
    )
