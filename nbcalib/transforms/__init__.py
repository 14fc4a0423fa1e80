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

The package's public API is the names below, imported from ``nbcalib.transforms``; the
modules are an implementation detail: :mod:`~nbcalib.transforms.validation` (input checks),
:mod:`~nbcalib.transforms.so3`, :mod:`~nbcalib.transforms.se3`,
:mod:`~nbcalib.transforms.quaternion` (xyzw quaternions, ``[x, y, z, qx, qy, qz, qw]`` poses)
and :mod:`~nbcalib.transforms.poses` (interpolation, pose errors, random samples).
"""

from __future__ import annotations

from nbcalib.transforms.poses import (
    interpolate_pose,
    offset_pose,
    pose_error,
    random_pose,
    random_rotation,
    slerp_rotation,
)
from nbcalib.transforms.quaternion import (
    matrix_to_quat_xyzw,
    pose_from_xyz_quat,
    pose_to_xyz_quat,
    quat_xyzw_to_matrix,
)
from nbcalib.transforms.se3 import (
    invert_T,
    make_T,
    se3_exp,
    se3_log,
    transform_points,
)
from nbcalib.transforms.so3 import (
    hat,
    rotation_angle_deg,
    so3_exp,
    so3_left_jacobian,
    so3_left_jacobian_inv,
    so3_log,
    vee,
)
from nbcalib.transforms.validation import (
    DEFAULT_ATOL,
    is_valid_T,
    validate_rotation,
    validate_T,
)

__all__ = [
    "DEFAULT_ATOL",
    "hat",
    "interpolate_pose",
    "invert_T",
    "is_valid_T",
    "make_T",
    "matrix_to_quat_xyzw",
    "offset_pose",
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
