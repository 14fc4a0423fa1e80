"""SO(3) / SE(3) kernels for use inside other kernels: one item at a time, no input checks.

Each function computes what its namesake in :mod:`nbcalib.transforms` computes for one item, with
the same formulas and the same small-angle series; the tests hold the two equal to ~1e-12. The
conventions are those of ``docs/conventions.md``: ``p_a = T_a_b @ p_b``, quaternions xyzw,
se(3) tangent ``xi = [v, omega]`` (translation first).

Arguments are C-contiguous float64 arrays (rotation vectors (3,), tangents (6,), quaternions
(4,) xyzw, rotations (3, 3), rigid transforms (4, 4)) and float scalars. Rotations are read from
the top-left 3 x 3 block, so a (4, 4) transform can be passed where a rotation is expected.

For hot loops, the ``*_into`` variants write into a caller's array and :func:`transform_point`
returns a tuple, so neither allocates; e.g. deskewing one point at fraction ``s``::

    interpolate_pose_into(T_world_lidar_0, T_world_lidar_1, s, T)
    x, y, z = transform_point(T, px, py, pz)
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels._jit import jit

# The same constants as nbcalib.transforms.so3 (a test checks it): below _SINC_TAYLOR, sin(x)/x
# is its Taylor series; below _JACOBIAN_TAYLOR, the SO(3) Jacobian coefficients are.
_SINC_TAYLOR = 1e-4
_JACOBIAN_TAYLOR = 1e-2


@jit
def _sinc(x):
    """sin(x) / x (unnormalised), by its Taylor series near 0."""
    if abs(x) < _SINC_TAYLOR:
        x2 = x * x
        return 1.0 - x2 / 6.0 + x2 * x2 / 120.0
    return math.sin(x) / x


# ---------------------------------------------------------------------------------------------
# SO(3)
# ---------------------------------------------------------------------------------------------


@jit
def _so3_exp_scalars_into(wx, wy, wz, out):
    """Rodrigues R = I + a K + b K^2 into out[:3, :3], with K^2 = w w^T - theta^2 I."""
    theta = math.sqrt(wx * wx + wy * wy + wz * wz)
    a = _sinc(theta)  # sin(theta) / theta
    h = _sinc(0.5 * theta)
    b = 0.5 * h * h  # (1 - cos(theta)) / theta^2
    out[0, 0] = 1.0 - b * (wy * wy + wz * wz)
    out[0, 1] = b * wx * wy - a * wz
    out[0, 2] = b * wx * wz + a * wy
    out[1, 0] = b * wx * wy + a * wz
    out[1, 1] = 1.0 - b * (wx * wx + wz * wz)
    out[1, 2] = b * wy * wz - a * wx
    out[2, 0] = b * wx * wz - a * wy
    out[2, 1] = b * wy * wz + a * wx
    out[2, 2] = 1.0 - b * (wx * wx + wy * wy)


@jit
def so3_exp_into(omega, out):
    """Rotation matrix of the rotation vector ``omega`` (3,) into ``out[:3, :3]``."""
    _so3_exp_scalars_into(omega[0], omega[1], omega[2], out)


@jit
def so3_exp(omega):
    """Rotation matrix (3, 3) of the rotation vector ``omega`` (3,)."""
    out = np.empty((3, 3))
    _so3_exp_scalars_into(omega[0], omega[1], omega[2], out)
    return out


@jit
def _so3_log_tuple(R):
    """Rotation vector (wx, wy, wz) of R[:3, :3]; see nbcalib.transforms.so3_log."""
    wx = 0.5 * (R[2, 1] - R[1, 2])  # w = sin(theta) * axis
    wy = 0.5 * (R[0, 2] - R[2, 0])
    wz = 0.5 * (R[1, 0] - R[0, 1])
    sin_theta = math.sqrt(wx * wx + wy * wy + wz * wz)
    cos_theta = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1.0)
    theta = math.atan2(sin_theta, cos_theta)
    if cos_theta >= 0.0:
        scale = 1.0 / _sinc(theta)  # theta / sin(theta)
        return scale * wx, scale * wy, scale * wz
    # Beyond 90 degrees: the axis is the column of (R + R^T)/2 - cos(theta) I = (1 - cos) a a^T
    # with the largest diagonal entry (first one on ties, as numpy.argmax), sign of w.
    d0 = R[0, 0] - cos_theta
    d1 = R[1, 1] - cos_theta
    d2 = R[2, 2] - cos_theta
    if d0 >= d1 and d0 >= d2:
        ax, ay, az = d0, 0.5 * (R[1, 0] + R[0, 1]), 0.5 * (R[2, 0] + R[0, 2])
    elif d1 >= d2:
        ax, ay, az = 0.5 * (R[0, 1] + R[1, 0]), d1, 0.5 * (R[2, 1] + R[1, 2])
    else:
        ax, ay, az = 0.5 * (R[0, 2] + R[2, 0]), 0.5 * (R[1, 2] + R[2, 1]), d2
    scale = theta / math.sqrt(ax * ax + ay * ay + az * az)
    if ax * wx + ay * wy + az * wz < 0.0:
        scale = -scale
    return scale * ax, scale * ay, scale * az


@jit
def so3_log(R):
    """Rotation vector (3,), angle in [0, pi], of the rotation ``R`` (3, 3)."""
    wx, wy, wz = _so3_log_tuple(R)
    out = np.empty(3)
    out[0], out[1], out[2] = wx, wy, wz
    return out


# ---------------------------------------------------------------------------------------------
# SE(3)
# ---------------------------------------------------------------------------------------------


@jit
def _cross(ax, ay, az, bx, by, bz):
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@jit
def se3_exp_into(xi, out):
    """Rigid transform of the tangent ``xi = [v, omega]`` (6,) into ``out`` (4, 4).

    ``R = so3_exp(omega)``, ``t = J_l(omega) v = v + b (w x v) + c (w x (w x v))``.
    """
    vx, vy, vz = xi[0], xi[1], xi[2]
    wx, wy, wz = xi[3], xi[4], xi[5]
    _so3_exp_scalars_into(wx, wy, wz, out)
    theta = math.sqrt(wx * wx + wy * wy + wz * wz)
    h = _sinc(0.5 * theta)
    b = 0.5 * h * h  # (1 - cos(theta)) / theta^2
    if theta < _JACOBIAN_TAYLOR:
        t2 = theta * theta
        c = 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0
    else:
        c = (1.0 - math.sin(theta) / theta) / (theta * theta)  # (theta - sin(theta)) / theta^3
    kx, ky, kz = _cross(wx, wy, wz, vx, vy, vz)
    kkx, kky, kkz = _cross(wx, wy, wz, kx, ky, kz)
    out[0, 3] = vx + b * kx + c * kkx
    out[1, 3] = vy + b * ky + c * kky
    out[2, 3] = vz + b * kz + c * kkz
    out[3, 0] = 0.0
    out[3, 1] = 0.0
    out[3, 2] = 0.0
    out[3, 3] = 1.0


@jit
def se3_exp(xi):
    """Rigid transform (4, 4) of the tangent ``xi = [v, omega]`` (6,)."""
    out = np.empty((4, 4))
    se3_exp_into(xi, out)
    return out


@jit
def se3_log(T):
    """Tangent ``[v, omega]`` (6,) of the rigid transform ``T`` (4, 4); ``v = J_l^-1 t``."""
    wx, wy, wz = _so3_log_tuple(T)
    theta = math.sqrt(wx * wx + wy * wy + wz * wz)
    if theta < _JACOBIAN_TAYLOR:
        t2 = theta * theta
        d = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0
    else:
        half_cot = math.cos(0.5 * theta) / _sinc(0.5 * theta)  # (theta/2) cot(theta/2)
        d = (1.0 - half_cot) / (theta * theta)
    tx, ty, tz = T[0, 3], T[1, 3], T[2, 3]
    kx, ky, kz = _cross(wx, wy, wz, tx, ty, tz)
    kkx, kky, kkz = _cross(wx, wy, wz, kx, ky, kz)
    out = np.empty(6)
    out[0] = tx - 0.5 * kx + d * kkx
    out[1] = ty - 0.5 * ky + d * kky
    out[2] = tz - 0.5 * kz + d * kkz
    out[3], out[4], out[5] = wx, wy, wz
    return out


@jit
def invert_T(T):
    """Inverse (4, 4) of the rigid transform ``T`` (4, 4): ``[[R^T, -R^T t], [0, 1]]``."""
    out = np.zeros((4, 4))
    for i in range(3):
        for j in range(3):
            out[i, j] = T[j, i]
    for i in range(3):
        out[i, 3] = -(T[0, i] * T[0, 3] + T[1, i] * T[1, 3] + T[2, i] * T[2, 3])
    out[3, 3] = 1.0
    return out


@jit
def compose_T(T_a_b, T_b_c):
    """Product ``T_a_c = T_a_b @ T_b_c`` (4, 4) of two rigid transforms."""
    out = np.zeros((4, 4))
    for i in range(3):
        for j in range(4):
            out[i, j] = T_a_b[i, 0] * T_b_c[0, j] + T_a_b[i, 1] * T_b_c[1, j]
            out[i, j] += T_a_b[i, 2] * T_b_c[2, j]
        out[i, 3] += T_a_b[i, 3]
    out[3, 3] = 1.0
    return out


@jit
def transform_point(T_a_b, x, y, z):
    """Point ``(x, y, z)`` of frame ``b`` in frame ``a``, as a tuple (allocation-free)."""
    return (
        T_a_b[0, 0] * x + T_a_b[0, 1] * y + T_a_b[0, 2] * z + T_a_b[0, 3],
        T_a_b[1, 0] * x + T_a_b[1, 1] * y + T_a_b[1, 2] * z + T_a_b[1, 3],
        T_a_b[2, 0] * x + T_a_b[2, 1] * y + T_a_b[2, 2] * z + T_a_b[2, 3],
    )


# ---------------------------------------------------------------------------------------------
# Quaternions (xyzw)
# ---------------------------------------------------------------------------------------------


@jit
def _quat_scalars_to_matrix_into(x, y, z, w, out):
    """Rotation of the quaternion (x, y, z, w), normalised here, into out[:3, :3]."""
    n = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    out[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    out[0, 1] = 2.0 * (x * y - z * w)
    out[0, 2] = 2.0 * (x * z + y * w)
    out[1, 0] = 2.0 * (x * y + z * w)
    out[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    out[1, 2] = 2.0 * (y * z - x * w)
    out[2, 0] = 2.0 * (x * z - y * w)
    out[2, 1] = 2.0 * (y * z + x * w)
    out[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@jit
def quat_to_matrix_into(q_xyzw, out):
    """Rotation of the quaternion ``q_xyzw`` (4,), normalised, into ``out[:3, :3]``."""
    _quat_scalars_to_matrix_into(q_xyzw[0], q_xyzw[1], q_xyzw[2], q_xyzw[3], out)


@jit
def quat_to_matrix(q_xyzw):
    """Rotation matrix (3, 3) of the quaternion ``q_xyzw`` (4,); it need not be unit length."""
    out = np.empty((3, 3))
    quat_to_matrix_into(q_xyzw, out)
    return out


@jit
def _matrix_to_quat_tuple(R):
    """Canonical unit quaternion (x, y, z, w) of R[:3, :3]: Shepperd's method.

    K = 4 q q^T is built from R (see nbcalib.transforms.matrix_to_quat_xyzw); q is its column
    with the largest diagonal entry (first one on ties, as numpy.argmax), normalised.
    """
    kx = 1.0 + R[0, 0] - R[1, 1] - R[2, 2]
    ky = 1.0 - R[0, 0] + R[1, 1] - R[2, 2]
    kz = 1.0 - R[0, 0] - R[1, 1] + R[2, 2]
    kw = 1.0 + R[0, 0] + R[1, 1] + R[2, 2]
    if kx >= ky and kx >= kz and kx >= kw:
        x, y, z, w = kx, R[0, 1] + R[1, 0], R[0, 2] + R[2, 0], R[2, 1] - R[1, 2]
    elif ky >= kz and ky >= kw:
        x, y, z, w = R[0, 1] + R[1, 0], ky, R[1, 2] + R[2, 1], R[0, 2] - R[2, 0]
    elif kz >= kw:
        x, y, z, w = R[0, 2] + R[2, 0], R[1, 2] + R[2, 1], kz, R[1, 0] - R[0, 1]
    else:
        x, y, z, w = R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1], kw
    n = math.sqrt(x * x + y * y + z * z + w * w)
    # canonical sign: w > 0; at w == 0 the first non-zero of x, y, z is positive
    lead = w
    if lead == 0.0:
        lead = x if x != 0.0 else (y if y != 0.0 else z)
    if lead < 0.0:
        n = -n
    return x / n, y / n, z / n, w / n


@jit
def matrix_to_quat(R):
    """Unit quaternion (4,) xyzw, ``qw >= 0``, of the rotation ``R`` (3, 3)."""
    x, y, z, w = _matrix_to_quat_tuple(R)
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = x, y, z, w
    return out


@jit
def _slerp_tuple(x0, y0, z0, w0, x1, y1, z1, w1, s):
    """Slerp of unit quaternions along the shorter arc, as a normalised tuple (x, y, z, w).

    With Omega the angle between q0 and q1 as 4-vectors, q = [sin((1-s) Omega) q0 +
    sin(s Omega) q1] / sin(Omega), written with sinc so that near-parallel inputs (Omega -> 0)
    take the Taylor branch instead of dividing 0 by 0.
    """
    if x0 * x1 + y0 * y1 + z0 * z1 + w0 * w1 < 0.0:  # q1 and -q1 are the same rotation
        x1, y1, z1, w1 = -x1, -y1, -z1, -w1
    dx, dy, dz, dw = x1 - x0, y1 - y0, z1 - z0, w1 - w0
    px, py, pz, pw = x1 + x0, y1 + y0, z1 + z0, w1 + w0
    # |q1 - q0| = 2 sin(Omega/2), |q1 + q0| = 2 cos(Omega/2): accurate at every angle
    omega = 2.0 * math.atan2(
        math.sqrt(dx * dx + dy * dy + dz * dz + dw * dw),
        math.sqrt(px * px + py * py + pz * pz + pw * pw),
    )
    k = _sinc(omega)
    c0 = (1.0 - s) * _sinc((1.0 - s) * omega) / k
    c1 = s * _sinc(s * omega) / k
    x, y, z, w = c0 * x0 + c1 * x1, c0 * y0 + c1 * y1, c0 * z0 + c1 * z1, c0 * w0 + c1 * w1
    n = math.sqrt(x * x + y * y + z * z + w * w)
    return x / n, y / n, z / n, w / n


@jit
def quat_slerp(q0, q1, s):
    """Slerp (4,) xyzw between the unit quaternions ``q0`` and ``q1`` at fraction ``s``.

    The shorter arc is taken (``q1`` is negated when ``q0 . q1 < 0``); the result has unit length
    but no canonical sign.
    """
    x, y, z, w = _slerp_tuple(q0[0], q0[1], q0[2], q0[3], q1[0], q1[1], q1[2], q1[3], s)
    out = np.empty(4)
    out[0], out[1], out[2], out[3] = x, y, z, w
    return out


@jit
def interpolate_pose_into(T0, T1, s, out):
    """Pose at fraction ``s`` between ``T0`` and ``T1`` (4, 4) into ``out`` (4, 4).

    Slerp of the rotations, lerp of the translations (GTSAM ``Pose3::interpolateRt``), as
    :func:`nbcalib.transforms.interpolate_pose`; no allocation.
    """
    x0, y0, z0, w0 = _matrix_to_quat_tuple(T0)
    x1, y1, z1, w1 = _matrix_to_quat_tuple(T1)
    x, y, z, w = _slerp_tuple(x0, y0, z0, w0, x1, y1, z1, w1, s)
    _quat_scalars_to_matrix_into(x, y, z, w, out)
    for i in range(3):
        out[i, 3] = (1.0 - s) * T0[i, 3] + s * T1[i, 3]
    out[3, 0] = 0.0
    out[3, 1] = 0.0
    out[3, 2] = 0.0
    out[3, 3] = 1.0


@jit
def interpolate_pose(T0, T1, s):
    """Pose (4, 4) at fraction ``s`` from ``T0`` to ``T1``; see :func:`interpolate_pose_into`."""
    out = np.empty((4, 4))
    interpolate_pose_into(T0, T1, s, out)
    return out
