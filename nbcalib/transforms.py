"""Rigid-body transforms: SO(3), SE(3), unit quaternions and pose interpolation, in NumPy.

Conventions (``docs/conventions.md``, binding):

- ``T_a_b`` is a 4 x 4 homogeneous matrix with ``p_a = T_a_b @ p_b``; transforms compose only
  when inner frames match, ``T_a_c = T_a_b @ T_b_c``.
- Quaternions are stored xyzw (scalar last), as in ROS and ``calib.json``.
- so(3) vectors ``omega`` are rotation vectors (axis times angle, radians). se(3) tangent vectors
  are translation first, ``xi = [v, omega]``, and :func:`se3_exp` is the group exponential,
  ``t = V(omega) v`` with ``V`` the left Jacobian of SO(3).

Functions take one item or a leading batch of ``N`` items where that is natural (``omega`` of
shape (3,) or (N, 3), ``T`` of shape (4, 4) or (N, 4, 4)) and return float64 arrays of the
matching shape. Inputs are checked: a wrong shape, a non-finite value, or a matrix that must be a
rotation (or a rigid transform) but is not, raises ``ValueError`` naming the argument.

The formulas are written to be read: these functions are the references of the numba kernels in
:mod:`nbcalib.kernels.lie`, which compute the same quantities one item at a time.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_ATOL",
    "hat",
    "interpolate_pose",
    "invert_T",
    "is_valid_T",
    "make_T",
    "matrix_to_quat_xyzw",
    "pose_error",
    "pose_from_xyz_quat",
    "pose_to_xyz_quat",
    "quat_xyzw_to_matrix",
    "random_pose",
    "random_rotation",
    "rotation_angle_deg",
    "se3_exp",
    "se3_log",
    "slerp_rotation",
    "so3_exp",
    "so3_left_jacobian",
    "so3_left_jacobian_inv",
    "so3_log",
    "transform_points",
    "validate_T",
    "validate_rotation",
    "vee",
]

FloatArray = NDArray[np.float64]

#: Tolerance of the rigidity checks: max |R^T R - I|, |det R - 1| and the last row of ``T``.
DEFAULT_ATOL = 1e-6

# Below this |x|, sin(x) / x is its Taylor series 1 - x^2/6 + x^4/120 (truncation < x^6/5040).
# nbcalib.kernels.lie uses the same constants.
_SINC_TAYLOR = 1e-4
# Below this angle, the Jacobian coefficients (theta - sin theta) / theta^3 and
# (1 - (theta/2) cot(theta/2)) / theta^2, which lose digits to cancellation, are Taylor series
# (truncation < 1e-17 relative).
_JACOBIAN_TAYLOR = 1e-2
# Quaternions shorter than this are rejected rather than normalised.
_QUAT_MIN_NORM = 1e-12

_EYE3 = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------------------------
# Input checks
# ---------------------------------------------------------------------------------------------


def _float_array(x: ArrayLike, name: str) -> FloatArray:
    try:
        return np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name} must be an array of numbers, got {type(x).__name__}") from exc


def _batch_arg(
    x: ArrayLike, name: str, shape: tuple[int, ...], *, batch: bool = True
) -> tuple[FloatArray, bool]:
    """``x`` as a C-contiguous float64 array of shape (N, *shape), and whether it was one item."""
    a = _float_array(x, name)
    single = a.shape == shape
    if not single and not (batch and a.ndim == len(shape) + 1 and a.shape[1:] == shape):
        expected = str(shape)
        if batch:
            expected += f" or (N, {', '.join(str(n) for n in shape)})"
        raise ValueError(f"{name} must have shape {expected}, got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} must be finite, but it holds NaN or inf")
    return np.ascontiguousarray(a.reshape((-1, *shape))), single


def _check_rotations(R: FloatArray, name: str, atol: float, single: bool) -> None:
    """Raise ValueError unless every R[n] of (N, 3, 3) is a rotation within ``atol``."""
    ortho = np.abs(np.swapaxes(R, 1, 2) @ R - _EYE3).max(axis=(1, 2))
    det = np.linalg.det(R)
    bad = np.flatnonzero((ortho > atol) | (np.abs(det - 1.0) > atol))
    if bad.size:
        k = bad[0]
        item = "" if single else f" (item {k})"
        raise ValueError(
            f"{name} is not a rotation matrix{item}: max|R^T R - I| = {ortho[k]:.2e}, "
            f"det = {det[k]:.6f} (tolerance {atol:g})"
        )


def _check_transforms(T: FloatArray, name: str, atol: float, single: bool) -> None:
    """Raise ValueError unless every T[n] of (N, 4, 4) is a rigid transform within ``atol``."""
    row = np.abs(T[:, 3, :] - _LAST_ROW).max(axis=1)
    bad = np.flatnonzero(row > atol)
    if bad.size:
        k = bad[0]
        item = "" if single else f" (item {k})"
        raise ValueError(f"{name} must have last row [0, 0, 0, 1]{item}, got {T[k, 3].tolist()}")
    _check_rotations(T[:, :3, :3], f"{name}[:3, :3]", atol, single)


def _rotation_arg(R: ArrayLike, name: str, *, batch: bool = True) -> tuple[FloatArray, bool]:
    R, single = _batch_arg(R, name, (3, 3), batch=batch)
    _check_rotations(R, name, DEFAULT_ATOL, single)
    return R, single


def _transform_arg(T: ArrayLike, name: str, *, batch: bool = True) -> tuple[FloatArray, bool]:
    T, single = _batch_arg(T, name, (4, 4), batch=batch)
    _check_transforms(T, name, DEFAULT_ATOL, single)
    return T, single


def _fractions(s: ArrayLike) -> tuple[FloatArray, bool]:
    """Interpolation fractions as (N,), and whether ``s`` was a scalar."""
    a = _float_array(s, "s")
    if a.ndim > 1:
        raise ValueError(f"s must be a scalar or have shape (N,), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("s must be finite, but it holds NaN or inf")
    return a.reshape(-1), a.ndim == 0


def _unbatch(x: FloatArray, single: bool) -> FloatArray:
    return x[0] if single else x


def validate_rotation(
    R: ArrayLike, name: str = "R", *, atol: float = DEFAULT_ATOL, batch: bool = False
) -> FloatArray:
    """Check that ``R`` is a rotation matrix and return it as C-contiguous float64.

    Parameters
    ----------
    R : array_like of shape (3, 3), or (N, 3, 3) when ``batch``
        The matrix (matrices) to check.
    name : str
        Name of the argument, used in the error message.
    atol : float
        Tolerance on ``max |R^T R - I|`` and ``|det R - 1|``.
    batch : bool
        Also accept a leading batch dimension.

    Returns
    -------
    ndarray of shape (3, 3) or (N, 3, 3), float64
        ``R`` itself when it already is C-contiguous float64.

    Raises
    ------
    ValueError
        Wrong shape, non-finite values, not orthonormal, or a reflection (det -1).
    """
    R_checked, single = _batch_arg(R, name, (3, 3), batch=batch)
    _check_rotations(R_checked, name, atol, single)
    return _unbatch(R_checked, single)


def validate_T(
    T: ArrayLike, name: str = "T", *, atol: float = DEFAULT_ATOL, batch: bool = False
) -> FloatArray:
    """Check that ``T`` is a rigid transform and return it as C-contiguous float64.

    A rigid transform is a finite 4 x 4 matrix whose top-left 3 x 3 block is a rotation
    (orthonormal, det +1) and whose last row is ``[0, 0, 0, 1]``, all within ``atol``.

    Parameters
    ----------
    T : array_like of shape (4, 4), or (N, 4, 4) when ``batch``
        The transform(s) to check, e.g. ``T_camera_lidar``.
    name : str
        Name of the argument, used in the error message.
    atol : float
        Tolerance of the rotation and last-row checks.
    batch : bool
        Also accept a leading batch dimension.

    Returns
    -------
    ndarray of shape (4, 4) or (N, 4, 4), float64
        ``T`` itself when it already is C-contiguous float64.

    Raises
    ------
    ValueError
        Naming ``name`` and what is wrong.
    """
    T_checked, single = _batch_arg(T, name, (4, 4), batch=batch)
    _check_transforms(T_checked, name, atol, single)
    return _unbatch(T_checked, single)


def is_valid_T(T: ArrayLike, *, atol: float = DEFAULT_ATOL) -> bool:
    """Whether ``T`` is one finite 4 x 4 rigid transform (see :func:`validate_T`).

    Parameters
    ----------
    T : array_like
        Anything; only a (4, 4) rigid transform gives True.
    atol : float
        Tolerance of the rotation and last-row checks.

    Returns
    -------
    bool
    """
    try:
        validate_T(T, atol=atol)
    except ValueError:
        return False
    return True


# ---------------------------------------------------------------------------------------------
# SO(3)
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# SE(3)
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# Quaternions (xyzw)
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# Interpolation, errors, random samples
# ---------------------------------------------------------------------------------------------


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
