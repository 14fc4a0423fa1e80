"""SE(3): building, inverting and applying rigid transforms, and the group exponential.

``T_a_b`` is 4 x 4 with ``p_a = T_a_b @ p_b``; se(3) tangent vectors are translation first,
``xi = [v, omega]``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nbcalib.transforms.so3 import _left_jacobian, _left_jacobian_inv, _so3_exp, _so3_log
from nbcalib.transforms.validation import (
    FloatArray,
    _batch_arg,
    _rotation_arg,
    _transform_arg,
    _unbatch,
)

__all__ = [
    "invert_T",
    "make_T",
    "se3_exp",
    "se3_log",
    "transform_points",
]


def _make_T(R: FloatArray, t: FloatArray) -> FloatArray:
    T = np.zeros((R.shape[0], 4, 4))
    T[:, :3, :3] = R
    T[:, :3, 3] = t
    T[:, 3, 3] = 1.0
    return T


def _se3_exp(xi: FloatArray) -> FloatArray:
    v, omega = xi[:, :3], xi[:, 3:]
    t = np.einsum("nij,nj->ni", _left_jacobian(omega), v)
    return _make_T(_so3_exp(omega), t)


def _se3_log(T: FloatArray) -> FloatArray:
    omega = _so3_log(T[:, :3, :3])
    v = np.einsum("nij,nj->ni", _left_jacobian_inv(omega), T[:, :3, 3])
    return np.concatenate([v, omega], axis=1)


def se3_exp(xi: ArrayLike) -> FloatArray:
    """Rigid transform of an se(3) tangent vector (the group exponential).

    ``R = so3_exp(omega)`` and ``t = J_l(omega) @ v`` (:func:`so3_left_jacobian`), i.e. the matrix
    exponential of the twist ``[[hat(omega), v], [0, 0]]``; not "rotation vector plus
    translation". Left perturbations update a pose as ``T <- se3_exp(delta) @ T``.

    Parameters
    ----------
    xi : array_like of shape (6,) or (N, 6)
        Tangent vector(s) ``[vx, vy, vz, wx, wy, wz]``, translation first (metres, radians).

    Returns
    -------
    ndarray of shape (4, 4) or (N, 4, 4), float64
    """
    xi, single = _batch_arg(xi, "xi", (6,))
    return _unbatch(_se3_exp(xi), single)


def se3_log(T: ArrayLike) -> FloatArray:
    """Tangent vector ``[v, omega]`` of a rigid transform, the inverse of :func:`se3_exp`.

    Parameters
    ----------
    T : array_like of shape (4, 4) or (N, 4, 4)
        Rigid transform(s).

    Returns
    -------
    ndarray of shape (6,) or (N, 6), float64
        ``[vx, vy, vz, wx, wy, wz]``, rotation angle in [0, pi]; ``v = J_l(omega)^-1 @ t``.
    """
    T, single = _transform_arg(T, "T")
    return _unbatch(_se3_log(T), single)


def make_T(R: ArrayLike, t: ArrayLike) -> FloatArray:
    """Homogeneous transform ``[[R, t], [0, 0, 0, 1]]``.

    Parameters
    ----------
    R : array_like of shape (3, 3) or (N, 3, 3)
        Rotation(s) ``R_a_b``.
    t : array_like of shape (3,) or (N, 3)
        Translation(s): the origin of frame ``b`` in frame ``a``, metres. Same batch as ``R``.

    Returns
    -------
    ndarray of shape (4, 4) or (N, 4, 4), float64
        ``T_a_b``.
    """
    R_b, single_R = _rotation_arg(R, "R")
    t_b, single_t = _batch_arg(t, "t", (3,))
    if single_R != single_t or R_b.shape[0] != t_b.shape[0]:
        raise ValueError(
            "R and t must both be single or hold the same number of items, got shapes "
            f"{np.shape(R)} and {np.shape(t)}"
        )
    return _unbatch(_make_T(R_b, t_b), single_R)


def invert_T(T: ArrayLike) -> FloatArray:
    """Inverse of a rigid transform, ``T_b_a = invert_T(T_a_b) = [[R^T, -R^T t], [0, 1]]``.

    Parameters
    ----------
    T : array_like of shape (4, 4) or (N, 4, 4)
        Rigid transform(s) ``T_a_b``.

    Returns
    -------
    ndarray of shape (4, 4) or (N, 4, 4), float64
        ``T_b_a``.
    """
    T, single = _transform_arg(T, "T")
    R_inv = np.swapaxes(T[:, :3, :3], 1, 2)
    return _unbatch(_make_T(R_inv, -np.einsum("nij,nj->ni", R_inv, T[:, :3, 3])), single)


def transform_points(T_a_b: ArrayLike, points_b: ArrayLike) -> FloatArray:
    """Map points from frame ``b`` to frame ``a``: ``p_a = R_a_b @ p_b + t_a_b``.

    Parameters
    ----------
    T_a_b : array_like of shape (4, 4)
        Rigid transform, frame ``b`` to frame ``a``.
    points_b : array_like of shape (N, 3) or (3,)
        Points in frame ``b``, metres.

    Returns
    -------
    ndarray of shape (N, 3) or (3,), float64
        ``points_a``, the same points in frame ``a``.
    """
    T, _ = _transform_arg(T_a_b, "T_a_b", batch=False)
    points, single = _batch_arg(points_b, "points_b", (3,))
    return _unbatch(points @ T[0, :3, :3].T + T[0, :3, 3], single)
