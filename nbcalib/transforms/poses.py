"""Pose interpolation, pose errors and random rotations and poses.

Interpolation slerps the rotation and lerps the translation (the constant-velocity model of
deskewing and continuous-time ICP); errors compare estimated and true transforms.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from nbcalib.transforms.quaternion import _quat_to_matrix
from nbcalib.transforms.se3 import _make_T
from nbcalib.transforms.so3 import _rotation_angle, _so3_exp, _so3_log
from nbcalib.transforms.validation import (
    FloatArray,
    _fractions,
    _rotation_arg,
    _transform_arg,
    _unbatch,
)

__all__ = [
    "interpolate_pose",
    "offset_pose",
    "pose_error",
    "random_pose",
    "random_rotation",
    "slerp_rotation",
]


def _slerp(R0: FloatArray, R1: FloatArray, s: FloatArray) -> FloatArray:
    """R0 exp(s log(R0^T R1)) for R0, R1 (3, 3) and s (N,): the shortest (geodesic) path."""
    omega = _so3_log((R0.T @ R1)[None])[0]
    return R0 @ _so3_exp(s[:, None] * omega)


def slerp_rotation(R0: ArrayLike, R1: ArrayLike, s: ArrayLike) -> FloatArray:
    """Spherical linear interpolation of rotations, ``R0 @ so3_exp(s * so3_log(R0^T @ R1))``.

    The path is the shorter arc (relative angle in [0, pi]) travelled at constant angular
    velocity; ``s = 0`` gives ``R0``, ``s = 1`` gives ``R1``, other values extrapolate.

    Parameters
    ----------
    R0, R1 : array_like of shape (3, 3)
        Rotations at ``s = 0`` and ``s = 1``.
    s : float or array_like of shape (N,)
        Interpolation fraction(s).

    Returns
    -------
    ndarray of shape (3, 3) for a scalar ``s``, else (N, 3, 3), float64
    """
    R0_c, _ = _rotation_arg(R0, "R0", batch=False)
    R1_c, _ = _rotation_arg(R1, "R1", batch=False)
    s_c, scalar = _fractions(s)
    return _unbatch(_slerp(R0_c[0], R1_c[0], s_c), scalar)


def interpolate_pose(T_0: ArrayLike, T_1: ArrayLike, s: ArrayLike) -> FloatArray:
    """Interpolate poses: slerp the rotation, lerp the translation (GTSAM ``Pose3::interpolateRt``).

    ``R(s) = R_0 @ so3_exp(s * so3_log(R_0^T @ R_1))`` and ``t(s) = (1 - s) t_0 + s t_1``: the
    model of a sensor moving at constant velocity between two poses, as used for deskewing and
    continuous-time ICP. Not the SE(3) geodesic (which would screw the translation).

    Parameters
    ----------
    T_0, T_1 : array_like of shape (4, 4)
        Poses of the same frame pair at ``s = 0`` and ``s = 1``, e.g. ``T_world_lidar`` at the
        start and end of a scan.
    s : float or array_like of shape (N,)
        Interpolation fraction(s), normally in [0, 1]; other values extrapolate.

    Returns
    -------
    ndarray of shape (4, 4) for a scalar ``s``, else (N, 4, 4), float64
    """
    T0, _ = _transform_arg(T_0, "T_0", batch=False)
    T1, _ = _transform_arg(T_1, "T_1", batch=False)
    s_c, scalar = _fractions(s)
    R = _slerp(T0[0, :3, :3], T1[0, :3, :3], s_c)
    t = (1.0 - s_c)[:, None] * T0[0, :3, 3] + s_c[:, None] * T1[0, :3, 3]
    return _unbatch(_make_T(R, t), scalar)


def pose_error(
    T_est_a_b: ArrayLike, T_true_a_b: ArrayLike
) -> tuple[float, float] | tuple[FloatArray, FloatArray]:
    """Translation and rotation error of an estimated transform.

    The rotation error is the angle of ``R_est @ R_true^T``; the translation error is
    ``|t_est - t_true|`` of the transforms as given, i.e. the distance between the estimated and
    true positions of the origin of ``b`` in frame ``a``. Pass ``T_lidar_camera`` (as stored in
    ``calib.json``) to get the displacement of the camera centre in the LiDAR frame, the figure
    the paper and the reference toolbox report.

    Parameters
    ----------
    T_est_a_b, T_true_a_b : array_like of shape (4, 4) or (N, 4, 4)
        Estimated and true transforms, same shape.

    Returns
    -------
    translation_error_m : float or ndarray of shape (N,)
        Metres.
    rotation_error_deg : float or ndarray of shape (N,)
        Degrees, in [0, 180].
    """
    T_est, single = _transform_arg(T_est_a_b, "T_est_a_b")
    T_true, single_true = _transform_arg(T_true_a_b, "T_true_a_b")
    if T_est.shape != T_true.shape or single != single_true:
        raise ValueError(
            "T_est_a_b and T_true_a_b must have the same shape, got "
            f"{np.shape(T_est_a_b)} and {np.shape(T_true_a_b)}"
        )
    translation = np.linalg.norm(T_est[:, :3, 3] - T_true[:, :3, 3], axis=1)
    rotation = np.degrees(_rotation_angle(T_est[:, :3, :3] @ np.swapaxes(T_true[:, :3, :3], 1, 2)))
    if single:
        return float(translation[0]), float(rotation[0])
    return translation, rotation


def random_rotation(rng: np.random.Generator | int, *, size: int | None = None) -> FloatArray:
    """Rotation(s) drawn uniformly (Haar measure) on SO(3).

    A normalised 4-vector of independent standard normals is uniform on the unit sphere of
    quaternions, hence a uniform rotation.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Generator, or the seed of a new one (the same seed gives the same sample).
    size : int, optional
        Number of rotations; ``None`` for one.

    Returns
    -------
    ndarray of shape (3, 3), or (size, 3, 3), float64
    """
    gen = np.random.default_rng(rng)
    q = gen.standard_normal((1 if size is None else int(size), 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return _unbatch(_quat_to_matrix(q), size is None)


def random_pose(
    rng: np.random.Generator | int,
    *,
    max_translation: float = 1.0,
    size: int | None = None,
) -> FloatArray:
    """Rigid transform(s) with a uniform rotation and a translation uniform in a ball.

    Parameters
    ----------
    rng : numpy.random.Generator or int
        Generator, or the seed of a new one (the same seed gives the same sample).
    max_translation : float
        Radius of the ball of translations, metres.
    size : int, optional
        Number of poses; ``None`` for one.

    Returns
    -------
    ndarray of shape (4, 4), or (size, 4, 4), float64
    """
    if not (np.isfinite(max_translation) and max_translation >= 0.0):
        raise ValueError(f"max_translation must be finite and >= 0, got {max_translation}")
    gen = np.random.default_rng(rng)
    n = 1 if size is None else int(size)
    R = random_rotation(gen, size=n)
    direction = gen.standard_normal((n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    radius = max_translation * gen.random(n) ** (1.0 / 3.0)
    return _unbatch(_make_T(R, radius[:, None] * direction), size is None)


def offset_pose(
    T_camera_lidar: ArrayLike, angle_deg: float, distance: float, rng: np.random.Generator | int
) -> FloatArray:
    """A start exactly ``angle_deg`` and ``distance`` from ``T_camera_lidar``, in random directions.

    The rotation of ``T_lidar_camera`` is turned by exactly ``angle_deg`` about a random axis
    (in the LiDAR frame) and the camera centre moved by exactly ``distance`` metres in a random
    direction, so that :func:`pose_error` of the result against the pose is exactly
    ``(distance, angle_deg)``. ``rng`` (a generator, or the seed of a new one) draws the axis,
    then the direction (three standard normals each). The report's restarts and the benchmarks'
    starts are made this way.

    Returns
    -------
    ndarray of shape (4, 4), float64
        The offset ``T_camera_lidar``.
    """
    from nbcalib.transforms.se3 import invert_T, make_T
    from nbcalib.transforms.so3 import so3_exp

    gen = np.random.default_rng(rng)
    axis, direction = gen.standard_normal(3), gen.standard_normal(3)
    axis /= np.linalg.norm(axis)
    direction /= np.linalg.norm(direction)
    T_lidar_camera = invert_T(np.asarray(T_camera_lidar, dtype=np.float64))
    R = so3_exp(math.radians(angle_deg) * axis) @ T_lidar_camera[:3, :3]
    return invert_T(make_T(R, T_lidar_camera[:3, 3] + distance * direction))
