"""Unit quaternions stored xyzw (scalar last), and poses as ``[x, y, z, qx, qy, qz, qw]``.

The xyzw order and the seven-number pose layout are those of ROS and ``calib.json``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nbcalib.transforms.se3 import _make_T
from nbcalib.transforms.validation import (
    FloatArray,
    _batch_arg,
    _rotation_arg,
    _transform_arg,
    _unbatch,
)

__all__ = [
    "matrix_to_quat_xyzw",
    "pose_from_xyz_quat",
    "pose_to_xyz_quat",
    "quat_xyzw_to_matrix",
]

# Quaternions shorter than this are rejected rather than normalised.
_QUAT_MIN_NORM = 1e-12


def _quat_to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrices of unit quaternions q (N, 4) xyzw."""
    x, y, z, w = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[:, 0, 1] = 2.0 * (x * y - z * w)
    R[:, 0, 2] = 2.0 * (x * z + y * w)
    R[:, 1, 0] = 2.0 * (x * y + z * w)
    R[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[:, 1, 2] = 2.0 * (y * z - x * w)
    R[:, 2, 0] = 2.0 * (x * z - y * w)
    R[:, 2, 1] = 2.0 * (y * z + x * w)
    R[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


def _canonical_quat(q: FloatArray) -> FloatArray:
    """Choose the sign with w > 0; at w == 0, the first non-zero of x, y, z is positive."""
    first = np.argmax(q[:, :3] != 0.0, axis=1)
    lead = np.where(q[:, 3] == 0.0, q[np.arange(q.shape[0]), first], q[:, 3])
    return np.where(lead[:, None] < 0.0, -q, q)


def _matrix_to_quat(R: FloatArray) -> FloatArray:
    """Shepperd's method: K = 4 q q^T from R (xyzw order); q is K's largest-diagonal column."""
    r = R
    K = np.empty((R.shape[0], 4, 4))
    K[:, 0, 0] = 1.0 + r[:, 0, 0] - r[:, 1, 1] - r[:, 2, 2]
    K[:, 1, 1] = 1.0 - r[:, 0, 0] + r[:, 1, 1] - r[:, 2, 2]
    K[:, 2, 2] = 1.0 - r[:, 0, 0] - r[:, 1, 1] + r[:, 2, 2]
    K[:, 3, 3] = 1.0 + r[:, 0, 0] + r[:, 1, 1] + r[:, 2, 2]
    K[:, 0, 1] = K[:, 1, 0] = r[:, 0, 1] + r[:, 1, 0]
    K[:, 0, 2] = K[:, 2, 0] = r[:, 0, 2] + r[:, 2, 0]
    K[:, 1, 2] = K[:, 2, 1] = r[:, 1, 2] + r[:, 2, 1]
    K[:, 0, 3] = K[:, 3, 0] = r[:, 2, 1] - r[:, 1, 2]
    K[:, 1, 3] = K[:, 3, 1] = r[:, 0, 2] - r[:, 2, 0]
    K[:, 2, 3] = K[:, 3, 2] = r[:, 1, 0] - r[:, 0, 1]
    # The largest diagonal entry 4 q_k^2 is >= 1, so its column divides by nothing small.
    k = np.argmax(np.diagonal(K, axis1=1, axis2=2), axis=1)
    q = K[np.arange(k.size), :, k]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return _canonical_quat(q)


def _quat_arg(q: ArrayLike, name: str) -> tuple[FloatArray, bool]:
    """Quaternions as (N, 4), normalised; zero-norm ones are rejected."""
    q, single = _batch_arg(q, name, (4,))
    norm = np.linalg.norm(q, axis=1, keepdims=True)
    if (norm < _QUAT_MIN_NORM).any():
        raise ValueError(f"{name} has zero norm and is not a rotation")
    return q / norm, single


def quat_xyzw_to_matrix(q_xyzw: ArrayLike) -> FloatArray:
    """Rotation matrix of a quaternion stored xyzw (scalar last), which is normalised first.

    Parameters
    ----------
    q_xyzw : array_like of shape (4,) or (N, 4)
        Quaternion(s) ``[qx, qy, qz, qw]``; any non-zero length. ``q`` and ``-q`` give the same
        rotation.

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64

    Raises
    ------
    ValueError
        Wrong shape, non-finite or zero-norm quaternion.
    """
    q, single = _quat_arg(q_xyzw, "q_xyzw")
    return _unbatch(_quat_to_matrix(q), single)


def matrix_to_quat_xyzw(R: ArrayLike) -> FloatArray:
    """Unit quaternion xyzw of a rotation matrix, with the canonical sign.

    Shepperd's method (robust at every angle). Of ``q`` and ``-q`` the one with ``qw > 0`` is
    returned; for half turns (``qw == 0``) the first non-zero of ``qx, qy, qz`` is positive, as
    SciPy's ``Rotation.as_quat(canonical=True)``.

    Parameters
    ----------
    R : array_like of shape (3, 3) or (N, 3, 3)
        Rotation matrix (matrices).

    Returns
    -------
    ndarray of shape (4,) or (N, 4), float64
        ``[qx, qy, qz, qw]``, unit length, ``qw >= 0``.
    """
    R, single = _rotation_arg(R, "R")
    return _unbatch(_matrix_to_quat(R), single)


def pose_from_xyz_quat(xyz_quat: ArrayLike) -> FloatArray:
    """Rigid transform from ``[x, y, z, qx, qy, qz, qw]`` (the ``calib.json`` layout).

    Parameters
    ----------
    xyz_quat : array_like of shape (7,) or (N, 7)
        Translation (metres) then quaternion xyzw; the quaternion is normalised.

    Returns
    -------
    ndarray of shape (4, 4) or (N, 4, 4), float64
    """
    v, single = _batch_arg(xyz_quat, "xyz_quat", (7,))
    q, _ = _quat_arg(v[:, 3:], "xyz_quat[3:] (quaternion)")
    return _unbatch(_make_T(_quat_to_matrix(q), v[:, :3]), single)


def pose_to_xyz_quat(T: ArrayLike) -> FloatArray:
    """``[x, y, z, qx, qy, qz, qw]`` of a rigid transform; inverse of :func:`pose_from_xyz_quat`.

    Parameters
    ----------
    T : array_like of shape (4, 4) or (N, 4, 4)
        Rigid transform(s).

    Returns
    -------
    ndarray of shape (7,) or (N, 7), float64
        Translation (metres) then unit quaternion xyzw with the canonical sign
        (:func:`matrix_to_quat_xyzw`).
    """
    T, single = _transform_arg(T, "T")
    return _unbatch(np.concatenate([T[:, :3, 3], _matrix_to_quat(T[:, :3, :3])], axis=1), single)
