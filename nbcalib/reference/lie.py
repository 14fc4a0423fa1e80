"""Slow, readable references of :mod:`nbcalib.kernels.lie`, built on SciPy.

They compute each quantity the textbook way, independently of nbcalib's own formulas: the SE(3)
exponential as the matrix exponential of the twist, rotations through
:class:`scipy.spatial.transform.Rotation` (whose quaternions are xyzw, as nbcalib's), slerp
through :class:`scipy.spatial.transform.Slerp`. :mod:`nbcalib.transforms` holds the vectorised
NumPy versions of the same formulas as the kernels.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm
from scipy.spatial.transform import Rotation, Slerp


def twist_matrix(xi: np.ndarray) -> np.ndarray:
    """The 4 x 4 matrix ``[[hat(omega), v], [0, 0]]`` of the tangent ``xi = [v, omega]`` (6,)."""
    v, (wx, wy, wz) = xi[:3], xi[3:]
    X = np.zeros((4, 4))
    X[:3, :3] = [[0.0, -wz, wy], [wz, 0.0, -wx], [-wy, wx, 0.0]]
    X[:3, 3] = v
    return X


def se3_exp(xi: np.ndarray) -> np.ndarray:
    """Rigid transform (4, 4) of ``xi = [v, omega]`` (6,): ``expm`` of its twist matrix."""
    return expm(twist_matrix(xi))


def so3_exp(omega: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of the rotation vector ``omega`` (3,)."""
    return Rotation.from_rotvec(omega).as_matrix()


def so3_log(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of the rotation ``R`` (3, 3)."""
    return Rotation.from_matrix(R).as_rotvec()


def quat_to_matrix(q_xyzw: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) of the quaternion ``q_xyzw`` (4,), normalised."""
    return Rotation.from_quat(q_xyzw).as_matrix()


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Canonical unit quaternion (4,) xyzw (``qw >= 0``) of the rotation ``R`` (3, 3)."""
    return Rotation.from_matrix(R).as_quat(canonical=True)


def quat_slerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    """Unit quaternion (4,) xyzw at fraction ``s`` of the shorter arc from ``q0`` to ``q1``."""
    return Slerp([0.0, 1.0], Rotation.from_quat([q0, q1]))(s).as_quat()


def interpolate_pose(T0: np.ndarray, T1: np.ndarray, s: float) -> np.ndarray:
    """Pose (4, 4) at fraction ``s`` in [0, 1]: slerp of the rotations, lerp of the translations."""
    T = np.eye(4)
    T[:3, :3] = Slerp([0.0, 1.0], Rotation.from_matrix([T0[:3, :3], T1[:3, :3]]))(s).as_matrix()
    T[:3, 3] = (1.0 - s) * T0[:3, 3] + s * T1[:3, 3]
    return T


def transform_point(T_a_b: np.ndarray, p_b: np.ndarray) -> np.ndarray:
    """Point (3,) in frame ``a`` of the point ``p_b`` (3,), in homogeneous coordinates."""
    return (T_a_b @ np.append(p_b, 1.0))[:3]
