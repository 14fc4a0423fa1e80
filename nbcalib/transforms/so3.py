"""SO(3): rotation vectors, Rodrigues' formula and its inverse, the left Jacobian, angles.

Rotation vectors ``omega`` are axis times angle (radians); ``hat(omega) @ x == cross(omega, x)``.
The numba kernels of :mod:`nbcalib.kernels.lie` use the same series thresholds (tested).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from nbcalib.transforms.validation import _EYE3, FloatArray, _batch_arg, _rotation_arg, _unbatch

__all__ = [
    "hat",
    "rotation_angle_deg",
    "so3_exp",
    "so3_left_jacobian",
    "so3_left_jacobian_inv",
    "so3_log",
    "vee",
]

# Below this |x|, sin(x) / x is its Taylor series 1 - x^2/6 + x^4/120 (truncation < x^6/5040).
# nbcalib.kernels.lie uses the same constants.
_SINC_TAYLOR = 1e-4
# Below this angle, the Jacobian coefficients (theta - sin theta) / theta^3 and
# (1 - (theta/2) cot(theta/2)) / theta^2, which lose digits to cancellation, are Taylor series
# (truncation < 1e-17 relative).
_JACOBIAN_TAYLOR = 1e-2


def _sinc(x: FloatArray) -> FloatArray:
    """sin(x) / x (unnormalised), by its Taylor series near 0."""
    small = np.abs(x) < _SINC_TAYLOR
    x_safe = np.where(small, 1.0, x)
    x2 = x * x
    return np.where(small, 1.0 - x2 / 6.0 + x2 * x2 / 120.0, np.sin(x_safe) / x_safe)


def _hat(omega: FloatArray) -> FloatArray:
    wx, wy, wz = omega[..., 0], omega[..., 1], omega[..., 2]
    K = np.zeros((*omega.shape[:-1], 3, 3))
    K[..., 0, 1], K[..., 0, 2] = -wz, wy
    K[..., 1, 0], K[..., 1, 2] = wz, -wx
    K[..., 2, 0], K[..., 2, 1] = -wy, wx
    return K


def _vee(K: FloatArray) -> FloatArray:
    """The vector of the antisymmetric part of K."""
    return 0.5 * np.stack(
        [K[..., 2, 1] - K[..., 1, 2], K[..., 0, 2] - K[..., 2, 0], K[..., 1, 0] - K[..., 0, 1]],
        axis=-1,
    )


def _so3_exp(omega: FloatArray) -> FloatArray:
    """Rodrigues: R = I + sin(theta)/theta K + (1 - cos(theta))/theta^2 K^2, K = hat(omega)."""
    theta = np.linalg.norm(omega, axis=-1)[..., None, None]
    K = _hat(omega)
    a = _sinc(theta)  # sin(theta) / theta
    b = 0.5 * _sinc(0.5 * theta) ** 2  # (1 - cos(theta)) / theta^2, without cancellation
    return _EYE3 + a * K + b * (K @ K)


def _so3_log(R: FloatArray) -> FloatArray:
    """Rotation vectors of R (N, 3, 3), angles in [0, pi]."""
    w = _vee(R)  # sin(theta) * axis
    sin_theta = np.linalg.norm(w, axis=-1)
    cos_theta = 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0)
    theta = np.arctan2(sin_theta, cos_theta)  # accurate at every angle, unlike arccos
    omega = w / _sinc(theta)[:, None]
    # Beyond 90 degrees sin(theta) -> 0 takes the axis's precision in w with it (and its sign at
    # pi): take the axis from the symmetric part, (R + R^T)/2 - cos(theta) I = (1 - cos) a a^T,
    # as its column with the largest diagonal entry, with the sign of w.
    far = cos_theta < 0.0
    if far.any():
        R_far, w_far = R[far], w[far]
        B = 0.5 * (R_far + np.swapaxes(R_far, 1, 2)) - cos_theta[far, None, None] * _EYE3
        k = np.argmax(np.diagonal(B, axis1=1, axis2=2), axis=1)
        axis = B[np.arange(k.size), :, k]
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        sign = np.where(np.einsum("ni,ni->n", axis, w_far) < 0.0, -1.0, 1.0)
        omega[far] = (sign * theta[far])[:, None] * axis
    return omega


def _left_jacobian(omega: FloatArray) -> FloatArray:
    """J_l = I + (1 - cos)/theta^2 K + (theta - sin)/theta^3 K^2."""
    theta = np.linalg.norm(omega, axis=-1)[..., None, None]
    K = _hat(omega)
    small = theta < _JACOBIAN_TAYLOR
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    b = 0.5 * _sinc(0.5 * theta) ** 2
    c = np.where(small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (1.0 - np.sin(t) / t) / t**2)
    return _EYE3 + b * K + c * (K @ K)


def _left_jacobian_inv(omega: FloatArray) -> FloatArray:
    """J_l^-1 = I - K/2 + (1 - (theta/2) cot(theta/2))/theta^2 K^2."""
    theta = np.linalg.norm(omega, axis=-1)[..., None, None]
    K = _hat(omega)
    small = theta < _JACOBIAN_TAYLOR
    t = np.where(small, 1.0, theta)
    t2 = theta * theta
    half_cot = np.cos(0.5 * t) / _sinc(0.5 * t)  # (theta/2) cot(theta/2)
    d = np.where(small, 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0, (1.0 - half_cot) / t**2)
    return _EYE3 - 0.5 * K + d * (K @ K)


def hat(omega: ArrayLike) -> FloatArray:
    """Skew-symmetric matrix of a 3-vector: ``hat(omega) @ x == cross(omega, x)``.

    Parameters
    ----------
    omega : array_like of shape (3,) or (N, 3)
        Vector(s).

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64
    """
    omega, single = _batch_arg(omega, "omega", (3,))
    return _unbatch(_hat(omega), single)


def vee(Omega: ArrayLike) -> FloatArray:
    """Vector of a skew-symmetric matrix, the inverse of :func:`hat`.

    Parameters
    ----------
    Omega : array_like of shape (3, 3) or (N, 3, 3)
        Matrix (matrices); only the antisymmetric part ``(Omega - Omega^T) / 2`` is read.

    Returns
    -------
    ndarray of shape (3,) or (N, 3), float64
    """
    Omega, single = _batch_arg(Omega, "Omega", (3, 3))
    return _unbatch(_vee(Omega), single)


def so3_exp(omega: ArrayLike) -> FloatArray:
    """Rotation matrix of a rotation vector (Rodrigues' formula).

    ``R = I + sin(theta)/theta K + (1 - cos(theta))/theta^2 K^2`` with ``K = hat(omega)`` and
    ``theta = |omega|``; below ``theta = 1e-4`` the coefficients are Taylor series.

    Parameters
    ----------
    omega : array_like of shape (3,) or (N, 3)
        Rotation vector(s): axis times angle, radians.

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64
    """
    omega, single = _batch_arg(omega, "omega", (3,))
    return _unbatch(_so3_exp(omega), single)


def so3_log(R: ArrayLike) -> FloatArray:
    """Rotation vector of a rotation matrix, the inverse of :func:`so3_exp`.

    The angle is ``atan2(|w|, (trace R - 1)/2)`` with ``w`` the vector of the antisymmetric part
    (accurate at every angle). Up to 90 degrees the axis is ``w / |w|``; beyond, it is read from
    the symmetric part ``(R + R^T)/2 - cos(theta) I = (1 - cos(theta)) a a^T``, which stays
    accurate up to and at pi, where ``w`` vanishes. At exactly pi the sign of the axis is
    arbitrary (both signs are the same rotation).

    Parameters
    ----------
    R : array_like of shape (3, 3) or (N, 3, 3)
        Rotation matrix (matrices).

    Returns
    -------
    ndarray of shape (3,) or (N, 3), float64
        Rotation vector(s) with angle in [0, pi].
    """
    R, single = _rotation_arg(R, "R")
    return _unbatch(_so3_log(R), single)


def so3_left_jacobian(omega: ArrayLike) -> FloatArray:
    """Left Jacobian of SO(3), ``J_l(omega)``.

    It maps a change of the rotation vector to the left perturbation it causes,
    ``so3_exp(omega + d) ~ so3_exp(J_l(omega) @ d) @ so3_exp(omega)``, and gives the translation
    of the SE(3) exponential, ``t = J_l(omega) @ v``:
    ``J_l = I + (1 - cos(theta))/theta^2 K + (theta - sin(theta))/theta^3 K^2``.

    Parameters
    ----------
    omega : array_like of shape (3,) or (N, 3)
        Rotation vector(s), radians.

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64
    """
    omega, single = _batch_arg(omega, "omega", (3,))
    return _unbatch(_left_jacobian(omega), single)


def so3_left_jacobian_inv(omega: ArrayLike) -> FloatArray:
    """Inverse of the left Jacobian of SO(3), in closed form.

    ``J_l^-1 = I - K/2 + (1 - (theta/2) cot(theta/2))/theta^2 K^2``, defined for
    ``theta = |omega| < 2 pi``.

    Parameters
    ----------
    omega : array_like of shape (3,) or (N, 3)
        Rotation vector(s), radians.

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64
    """
    omega, single = _batch_arg(omega, "omega", (3,))
    return _unbatch(_left_jacobian_inv(omega), single)


def _rotation_angle(R: FloatArray) -> FloatArray:
    """Angle in [0, pi] of R (N, 3, 3), accurate near 0 and pi."""
    return np.arctan2(np.linalg.norm(_vee(R), axis=-1), 0.5 * (np.trace(R, axis1=1, axis2=2) - 1.0))


def rotation_angle_deg(R: ArrayLike) -> float | FloatArray:
    """Rotation angle of a rotation matrix, in degrees.

    Parameters
    ----------
    R : array_like of shape (3, 3) or (N, 3, 3)
        Rotation matrix (matrices).

    Returns
    -------
    float or ndarray of shape (N,), float64
        Angle(s) in [0, 180] degrees.
    """
    R, single = _rotation_arg(R, "R")
    angle = np.degrees(_rotation_angle(R))
    return float(angle[0]) if single else angle
