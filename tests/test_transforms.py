"""Rigid-body transforms: known answers, group algebra, exp/log, quaternions, interpolation.

NumPy functions (nbcalib.transforms) are checked against hand-worked answers, SciPy (Rotation
uses xyzw quaternions, expm gives the true group exponential) and their own algebra; the numba
kernels (nbcalib.kernels.lie) are checked against the NumPy functions and the SciPy references.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose
from scipy.linalg import expm
from scipy.spatial.transform import Rotation

from nbcalib import transforms as tf
from nbcalib.kernels import lie
from nbcalib.reference import lie as ref
from nbcalib.transforms import so3
from tests import strategies as S
from tests.tolerances import TOL

FAST = settings(max_examples=60, deadline=None)

# quarter turns about x, y, z: the images of the unit vectors are the columns
RX90 = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
RY90 = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
RZ90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
QUARTER_TURNS = [(0, RX90), (1, RY90), (2, RZ90)]


def assert_rel_close(actual, desired, rtol=TOL["transform_relative"]["rtol"]):
    """|actual - desired| <= rtol |desired| in the 2-norm (exact when desired is 0)."""
    actual, desired = np.asarray(actual), np.asarray(desired)
    error = np.linalg.norm(actual - desired)
    assert error <= rtol * np.linalg.norm(desired), (actual, desired, error)


def make_pose(R, t):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def rot(axis: int, angle: float) -> np.ndarray:
    return Rotation.from_rotvec(angle * np.eye(3)[axis]).as_matrix()


# ---------------------------------------------------------------------------------------------
# Known answers
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("axis", "R_expected"), QUARTER_TURNS)
def test_quarter_turns_about_each_axis(axis, R_expected):
    omega = 0.5 * math.pi * np.eye(3)[axis]
    q = np.append(math.sin(math.pi / 4) * np.eye(3)[axis], math.cos(math.pi / 4))
    assert_allclose(tf.so3_exp(omega), R_expected, rtol=0, atol=1e-15)
    assert_allclose(tf.so3_log(R_expected), omega, rtol=0, atol=1e-15)
    assert_allclose(tf.quat_xyzw_to_matrix(q), R_expected, rtol=0, atol=1e-15)
    assert_allclose(tf.matrix_to_quat_xyzw(R_expected), q, rtol=0, atol=1e-15)
    assert tf.rotation_angle_deg(R_expected) == pytest.approx(90.0, abs=1e-12)
    # x -> y -> z -> x: a quarter turn about one axis takes the next axis to the one after it
    nxt, after = np.eye(3)[(axis + 1) % 3], np.eye(3)[(axis + 2) % 3]
    assert_allclose(tf.so3_exp(omega) @ nxt, after, rtol=0, atol=1e-15)


def test_pose_from_xyz_quat_known_answer():
    # rotate 90 degrees about z, then translate by (1, 2, 3): (1, 0, 0) -> (0, 1, 0) -> (1, 3, 3)
    c = math.cos(math.pi / 4)
    T_a_b = tf.pose_from_xyz_quat([1.0, 2.0, 3.0, 0.0, 0.0, c, c])
    assert_allclose(T_a_b[:3, :3], RZ90, rtol=0, atol=1e-15)
    assert_allclose(T_a_b[:3, 3], [1.0, 2.0, 3.0], rtol=0, atol=0)
    assert_allclose(T_a_b[3], [0.0, 0.0, 0.0, 1.0], rtol=0, atol=0)
    assert_allclose(tf.transform_points(T_a_b, [1.0, 0.0, 0.0]), [1.0, 3.0, 3.0], atol=1e-15)
    assert_allclose(tf.pose_to_xyz_quat(T_a_b), [1.0, 2.0, 3.0, 0.0, 0.0, c, c], atol=1e-15)


def test_composition_order_on_points():
    T_a_b = make_pose(np.eye(3), [1.0, 0.0, 0.0])  # b is 1 m along x of a
    T_b_c = make_pose(RZ90, [0.0, 0.0, 0.0])  # c is b turned 90 degrees about z
    p_c = np.array([1.0, 0.0, 0.0])
    p_b = tf.transform_points(T_b_c, p_c)
    assert_allclose(p_b, [0.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(tf.transform_points(T_a_b, p_b), [1.0, 1.0, 0.0], atol=1e-15)
    assert_allclose(tf.transform_points(T_a_b @ T_b_c, p_c), [1.0, 1.0, 0.0], atol=1e-15)
    # the other order is a different transform
    assert_allclose(tf.transform_points(T_b_c @ T_a_b, p_c), [0.0, 2.0, 0.0], atol=1e-15)


def test_invert_T_known_answer():
    T_a_b = make_pose(RZ90, [1.0, 2.0, 3.0])
    T_b_a = tf.invert_T(T_a_b)
    assert_allclose(T_b_a[:3, :3], RZ90.T, atol=0)
    assert_allclose(T_b_a[:3, 3], -RZ90.T @ [1.0, 2.0, 3.0], atol=1e-15)  # = (-2, 1, -3)
    assert_allclose(tf.transform_points(T_b_a, [1.0, 2.0, 3.0]), [0.0, 0.0, 0.0], atol=1e-15)


def test_half_turn_quaternions_have_scipy_canonical_sign():
    for axis in range(3):
        R = rot(axis, math.pi)
        q = tf.matrix_to_quat_xyzw(R)
        assert_allclose(q, np.append(np.eye(3)[axis], 0.0), atol=1e-15)
        assert_allclose(lie.matrix_to_quat(R), q, atol=1e-15)
    # half turns R = 2 a a^T - I (exact in float64, so qw == 0 exactly): the first non-zero of
    # qx, qy, qz is made positive, as SciPy's canonical form
    for axis, R in [
        ([0.0, 1.0, -1.0], [[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0]]),
        ([1.0, -2.0, 0.0], [[-0.6, -0.8, 0.0], [-0.8, 0.6, 0.0], [0.0, 0.0, -1.0]]),
    ]:
        expected = np.append(axis / np.linalg.norm(axis), 0.0)
        assert_allclose(Rotation.from_matrix(R).as_quat(canonical=True), expected, atol=1e-15)
        assert_allclose(tf.matrix_to_quat_xyzw(R), expected, atol=1e-15)
        assert_allclose(lie.matrix_to_quat(np.array(R)), expected, atol=1e-15)


@pytest.mark.parametrize("axis", [np.array([1.0, 0.0, 0.0]), np.array([1.0, -2.0, 0.5])])
def test_log_at_exactly_pi(axis):
    axis = axis / np.linalg.norm(axis)
    R = Rotation.from_rotvec(math.pi * axis).as_matrix()
    for log in (tf.so3_log, lie.so3_log):
        omega = log(R)
        assert np.linalg.norm(omega) == pytest.approx(math.pi, abs=1e-14)
        assert abs(omega @ axis) == pytest.approx(math.pi, abs=1e-14)  # +-pi about the axis
        assert_allclose(tf.so3_exp(omega), R, **TOL["transform"])


def test_rotation_angle_and_pose_error_known_answers():
    assert tf.rotation_angle_deg(np.eye(3)) == 0.0
    assert tf.rotation_angle_deg(rot(1, math.radians(30.0))) == pytest.approx(30.0, abs=1e-12)
    assert tf.rotation_angle_deg(rot(2, math.pi)) == pytest.approx(180.0, abs=1e-12)
    angles = tf.rotation_angle_deg(np.stack([rot(0, 0.1), rot(1, 0.2)]))
    assert_allclose(angles, np.degrees([0.1, 0.2]), atol=1e-12)

    T_true = make_pose(rot(2, 0.3), [1.0, 2.0, 3.0])
    T_est = make_pose(rot(0, math.radians(2.0)) @ rot(2, 0.3), [1.03, 2.0, 3.04])
    t_err, r_err = tf.pose_error(T_est, T_true)
    assert t_err == pytest.approx(0.05, abs=1e-12)
    assert r_err == pytest.approx(2.0, abs=1e-12)
    t_errs, r_errs = tf.pose_error(np.stack([T_est, T_true]), np.stack([T_true, T_true]))
    assert_allclose(t_errs, [0.05, 0.0], atol=1e-12)
    assert_allclose(r_errs, [2.0, 0.0], atol=1e-12)


# ---------------------------------------------------------------------------------------------
# Group axioms and composition
# ---------------------------------------------------------------------------------------------


@FAST
@given(S.poses())
def test_identity_and_inverse(T):
    assert_allclose(T @ np.eye(4), T, atol=0)
    assert_allclose(tf.se3_exp(np.zeros(6)), np.eye(4), atol=0)
    assert_allclose(tf.se3_log(np.eye(4)), np.zeros(6), atol=0)
    T_inv = tf.invert_T(T)
    assert_allclose(T @ T_inv, np.eye(4), **TOL["transform"])
    assert_allclose(T_inv @ T, np.eye(4), **TOL["transform"])
    assert_allclose(tf.invert_T(T_inv), T, **TOL["transform"])
    assert_allclose(T_inv, np.linalg.inv(T), **TOL["transform"])


@FAST
@given(S.se3_tangents())
def test_exp_of_negative_tangent_is_the_inverse(xi):
    assert_allclose(tf.se3_exp(-xi), tf.invert_T(tf.se3_exp(xi)), **TOL["transform"])


@FAST
@given(S.poses(), S.poses(), S.poses(), S.point_clouds())
def test_composition_is_associative_and_acts_on_points(T_a_b, T_b_c, T_c_d, points_d):
    assert_allclose((T_a_b @ T_b_c) @ T_c_d, T_a_b @ (T_b_c @ T_c_d), **TOL["transform"])
    points_a = tf.transform_points(T_a_b, tf.transform_points(T_b_c, points_d))
    assert points_a.shape == points_d.shape
    # transform_points(T_a_b @ T_b_c, p) == transform_points(T_a_b, transform_points(T_b_c, p))
    assert_allclose(tf.transform_points(T_a_b @ T_b_c, points_d), points_a, rtol=1e-9, atol=1e-9)
    homogeneous = np.hstack([points_d, np.ones((len(points_d), 1))]) @ (T_a_b @ T_b_c).T
    assert_allclose(points_a, homogeneous[:, :3], rtol=1e-9, atol=1e-9)


def test_batched_functions_match_single_items(rng):
    Ts = tf.random_pose(rng, max_translation=5.0, size=7)
    xis = tf.se3_log(Ts)
    assert xis.shape == (7, 6)
    assert_allclose(xis, np.stack([tf.se3_log(T) for T in Ts]), atol=0)
    assert_allclose(tf.se3_exp(xis), np.stack([tf.se3_exp(xi) for xi in xis]), atol=0)
    assert_allclose(tf.invert_T(Ts), np.stack([tf.invert_T(T) for T in Ts]), atol=0)
    v7 = tf.pose_to_xyz_quat(Ts)
    assert_allclose(v7, np.stack([tf.pose_to_xyz_quat(T) for T in Ts]), atol=0)
    assert_allclose(tf.pose_from_xyz_quat(v7), Ts, **TOL["transform"])
    assert_allclose(tf.make_T(Ts[:, :3, :3], Ts[:, :3, 3]), Ts, atol=0)
    assert_allclose(tf.hat(xis[:, 3:]), np.stack([tf.hat(w) for w in xis[:, 3:]]), atol=0)
    assert_allclose(tf.vee(tf.hat(xis[:, 3:])), xis[:, 3:], atol=0)
    assert tf.transform_points(Ts[0], np.zeros((0, 3))).shape == (0, 3)


# ---------------------------------------------------------------------------------------------
# so(3) and se(3): exp, log, Jacobians
# ---------------------------------------------------------------------------------------------


@FAST
@given(S.rotation_vectors())
def test_so3_exp_matches_scipy_and_log_inverts_it(omega):
    R = tf.so3_exp(omega)
    assert tf.is_valid_T(make_pose(R, np.zeros(3)), atol=1e-12)
    assert_allclose(R, ref.so3_exp(omega), **TOL["transform"])
    # the antisymmetric part sin(theta) * axis keeps its relative precision near the identity
    assert_rel_close(tf.vee(R), tf.vee(ref.so3_exp(omega)))
    assert_rel_close(tf.so3_log(R), omega)
    assert_rel_close(ref.so3_log(R), omega)  # SciPy agrees on the reading of R


@FAST
@given(S.rotation_matrices())
def test_so3_log_then_exp_is_identity(R):
    assert_allclose(tf.so3_exp(tf.so3_log(R)), R, **TOL["transform"])
    # angles stop at pi - 1e-9 (strategies.NEAR_PI_MIN_GAP), where the sign is still defined
    assert_allclose(tf.so3_log(R), ref.so3_log(R), **TOL["transform"])


@FAST
@given(S.se3_tangents())
def test_se3_exp_is_the_matrix_exponential_of_the_twist(xi):
    T = tf.se3_exp(xi)
    assert_allclose(T, expm(ref.twist_matrix(xi)), **TOL["transform"])
    # translation first: xi[:3] is v, xi[3:] the rotation vector
    assert_allclose(T[:3, :3], tf.so3_exp(xi[3:]), atol=0)
    assert_rel_close(tf.se3_log(T), xi)


@FAST
@given(S.poses())
def test_se3_log_then_exp_is_identity(T):
    assert_allclose(tf.se3_exp(tf.se3_log(T)), T, **TOL["transform"])


def test_se3_exp_without_rotation_is_a_translation():
    assert_allclose(tf.se3_exp([1.0, 2.0, 3.0, 0.0, 0.0, 0.0]), make_pose(np.eye(3), [1, 2, 3]))
    # with rotation, t = J_l(omega) v, not v: a half turn about z carries v = (0, pi, 0)
    # around a half circle of radius 1 to t = (-2, 0, 0)
    T = tf.se3_exp([0.0, math.pi, 0.0, 0.0, 0.0, math.pi])
    assert_allclose(T[:3, 3], [-2.0, 0.0, 0.0], atol=1e-15)


# angles on both sides of the Taylor thresholds (1e-4 for sinc, 1e-2 for the Jacobians)
THRESHOLD_ANGLES = [0.0, 1e-9, 0.99e-4, 1.01e-4, 0.99e-2, 1.01e-2, 1.0, 3.0, math.pi]


@pytest.mark.parametrize("angle", THRESHOLD_ANGLES)
def test_left_jacobian_is_the_translation_part_of_expm(angle):
    omega = angle * np.array([2.0, -1.0, 2.0]) / 3.0
    J_expm = np.stack(
        [expm(ref.twist_matrix(np.append(e, omega)))[:3, 3] for e in np.eye(3)], axis=1
    )
    assert_allclose(tf.so3_left_jacobian(omega), J_expm, rtol=0, atol=1e-14)
    J_inv = tf.so3_left_jacobian_inv(omega)
    assert_allclose(J_inv @ tf.so3_left_jacobian(omega), np.eye(3), rtol=0, atol=1e-14)
    assert_allclose(J_inv, np.linalg.inv(J_expm), rtol=0, atol=1e-13)
    # and the kernels use the same series: t of se3_exp is J_l v
    for e in np.eye(3):
        xi = np.append(e, omega)
        assert_allclose(lie.se3_exp(xi)[:3, 3], J_expm @ e, rtol=0, atol=1e-14)
        assert_allclose(lie.se3_log(lie.se3_exp(xi)), xi, rtol=0, atol=1e-13)


@FAST
@given(S.rotation_vectors())
def test_left_jacobian_against_finite_differences(omega):
    # so3_exp(omega + d) = so3_exp(J_l(omega) d) so3_exp(omega) to first order in d
    h = 1e-6
    R_inv = tf.so3_exp(omega).T
    columns = [
        (
            tf.so3_log(tf.so3_exp(omega + h * e) @ R_inv)
            - tf.so3_log(tf.so3_exp(omega - h * e) @ R_inv)
        )
        / (2 * h)
        for e in np.eye(3)
    ]
    J_fd = np.stack(columns, axis=1)
    assert_allclose(tf.so3_left_jacobian(omega), J_fd, **TOL["jacobian_vs_finite_diff"])


def test_taylor_thresholds_are_shared_with_the_kernels():
    assert lie._SINC_TAYLOR == so3._SINC_TAYLOR
    assert lie._JACOBIAN_TAYLOR == so3._JACOBIAN_TAYLOR


# ---------------------------------------------------------------------------------------------
# Quaternions (xyzw)
# ---------------------------------------------------------------------------------------------


@FAST
@given(S.unit_quaternions(), st.floats(1e-3, 1e3))
def test_quaternion_order_is_xyzw_as_scipy(q, scale):
    R = tf.quat_xyzw_to_matrix(scale * q)  # normalised first
    assert_allclose(R, Rotation.from_quat(q).as_matrix(), **TOL["transform"])
    assert_allclose(tf.quat_xyzw_to_matrix(-q), R, **TOL["transform"])  # q and -q: one rotation
    q_back = tf.matrix_to_quat_xyzw(R)
    assert q_back[3] >= 0.0
    assert np.linalg.norm(q_back) == pytest.approx(1.0, abs=1e-15)
    assert_allclose(q_back, q if q[3] > 0 else -q, **TOL["transform"])
    assert_allclose(q_back, Rotation.from_matrix(R).as_quat(canonical=True), **TOL["transform"])


@FAST
@given(S.poses())
def test_xyz_quat_round_trip(T):
    v7 = tf.pose_to_xyz_quat(T)
    assert v7[6] >= 0.0
    assert_allclose(v7[:3], T[:3, 3], atol=0)
    assert_allclose(tf.pose_from_xyz_quat(v7), T, **TOL["transform"])
    assert_allclose(tf.pose_from_xyz_quat(np.append(v7[:3], -v7[3:])), T, **TOL["transform"])


# ---------------------------------------------------------------------------------------------
# Interpolation
# ---------------------------------------------------------------------------------------------


@FAST
@given(S.poses(), S.poses())
def test_interpolation_endpoints(T_0, T_1):
    assert_allclose(tf.interpolate_pose(T_0, T_1, 0.0), T_0, **TOL["transform"])
    assert_allclose(tf.interpolate_pose(T_0, T_1, 1.0), T_1, **TOL["transform"])
    assert_allclose(tf.interpolate_pose(T_0, T_1, [0.0, 1.0]), [T_0, T_1], **TOL["transform"])


@FAST
@given(S.poses(), S.rotation_vectors(), S.translations(), S.fractions())
def test_interpolation_is_constant_velocity(T_0, omega, d, s):
    # the body turns by omega (in its own frame) and moves by d (in the parent frame) from T_0
    # to T_1 at constant rate; at fraction s it has turned by s * omega and moved by s * d
    T_1 = make_pose(T_0[:3, :3] @ tf.so3_exp(omega), T_0[:3, 3] + d)
    expected = make_pose(T_0[:3, :3] @ tf.so3_exp(s * omega), T_0[:3, 3] + s * d)
    assert_allclose(tf.interpolate_pose(T_0, T_1, s), expected, **TOL["transform"])
    assert_allclose(tf.interpolate_pose(T_0, T_1, 0.5)[:3, 3], T_0[:3, 3] + 0.5 * d, atol=1e-12)
    assert_allclose(
        tf.slerp_rotation(T_0[:3, :3], T_1[:3, :3], s), expected[:3, :3], **TOL["transform"]
    )
    assert_allclose(ref.interpolate_pose(T_0, T_1, s), expected, **TOL["transform"])


def test_interpolation_midpoint_known_answer():
    T_0 = np.eye(4)
    T_1 = make_pose(RZ90, [2.0, 0.0, 0.0])
    T_half = tf.interpolate_pose(T_0, T_1, 0.5)
    assert_allclose(T_half, make_pose(rot(2, math.pi / 4), [1.0, 0.0, 0.0]), atol=1e-15)
    Ts = tf.interpolate_pose(T_0, T_1, np.linspace(0.0, 1.0, 5))
    assert Ts.shape == (5, 4, 4)
    assert_allclose(tf.rotation_angle_deg(Ts[:, :3, :3]), [0.0, 22.5, 45.0, 67.5, 90.0], atol=1e-12)
    assert tf.slerp_rotation(np.eye(3), RZ90, [0.25, 0.5]).shape == (2, 3, 3)


def test_interpolation_takes_the_shorter_arc():
    # 200 degrees one way is 160 degrees the other: the midpoint is 80 degrees the short way
    T_half = tf.interpolate_pose(
        np.eye(4), make_pose(rot(2, math.radians(200.0)), np.zeros(3)), 0.5
    )
    assert_allclose(T_half[:3, :3], rot(2, math.radians(-80.0)), atol=1e-14)


# ---------------------------------------------------------------------------------------------
# Kernels == NumPy functions == SciPy references
# ---------------------------------------------------------------------------------------------

KERNEL = TOL["kernel_vs_reference"]


@FAST
@given(S.se3_tangents())
def test_kernels_exp_log_match_numpy(xi):
    omega = np.ascontiguousarray(xi[3:])
    R = lie.so3_exp(omega)
    assert_allclose(R, tf.so3_exp(omega), **KERNEL)
    assert_rel_close(lie.so3_log(R), tf.so3_log(R), rtol=KERNEL["rtol"])
    T = lie.se3_exp(xi)
    assert_allclose(T, tf.se3_exp(xi), **KERNEL)
    assert_rel_close(lie.se3_log(T), tf.se3_log(T), rtol=KERNEL["rtol"])
    out = np.full((4, 4), np.nan)
    lie.se3_exp_into(xi, out)
    assert_allclose(out, T, atol=0)
    lie.so3_exp_into(omega, out)  # writes the rotation block only
    assert_allclose(out, T, atol=0)


@FAST
@given(S.poses(), S.poses(), S.point_clouds(max_points=4))
def test_kernels_pose_algebra_match_numpy(T_a_b, T_b_c, points_b):
    assert_allclose(lie.invert_T(T_a_b), tf.invert_T(T_a_b), **KERNEL)
    assert_allclose(lie.compose_T(T_a_b, T_b_c), T_a_b @ T_b_c, **KERNEL)
    points_a = tf.transform_points(T_a_b, points_b)
    for p_b, p_a in zip(points_b, points_a):
        assert_allclose(lie.transform_point(T_a_b, p_b[0], p_b[1], p_b[2]), p_a, **KERNEL)
        assert_allclose(ref.transform_point(T_a_b, p_b), p_a, **KERNEL)


@FAST
@given(S.unit_quaternions(), S.rotation_matrices())
def test_kernels_quaternions_match_numpy_and_scipy(q, R):
    assert_allclose(lie.quat_to_matrix(q), tf.quat_xyzw_to_matrix(q), **KERNEL)
    assert_allclose(lie.quat_to_matrix(3.0 * q), ref.quat_to_matrix(q), **KERNEL)
    assert_allclose(lie.matrix_to_quat(R), tf.matrix_to_quat_xyzw(R), **KERNEL)
    assert_allclose(lie.matrix_to_quat(R), ref.matrix_to_quat(R), **TOL["transform"])
    out = np.zeros((4, 4))
    lie.quat_to_matrix_into(q, out)
    assert_allclose(out[:3, :3], tf.quat_xyzw_to_matrix(q), **KERNEL)


@FAST
@given(S.unit_quaternions(), S.unit_quaternions(), S.fractions())
def test_kernel_slerp_matches_scipy(q0, q1, s):
    q = lie.quat_slerp(q0, q1, s)
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-15)
    expected = ref.quat_slerp(q0, q1, s)
    assert_allclose(q * np.sign(q @ expected), expected, **TOL["transform"])


@FAST
@given(S.poses(), S.poses(), S.fractions())
def test_kernel_interpolation_matches_numpy(T_0, T_1, s):
    # away from a relative half turn, where "the shorter arc" is undefined
    assume(tf.rotation_angle_deg(T_0[:3, :3].T @ T_1[:3, :3]) < 179.999)
    expected = tf.interpolate_pose(T_0, T_1, s)
    assert_allclose(lie.interpolate_pose(T_0, T_1, s), expected, **KERNEL)
    out = np.full((4, 4), np.nan)
    lie.interpolate_pose_into(T_0, T_1, s, out)
    assert_allclose(out, expected, **KERNEL)


def test_kernel_slerp_of_parallel_quaternions():
    q = np.array([0.1, -0.2, 0.3, 0.9])
    q /= np.linalg.norm(q)
    for other in (q, -q, q + 1e-13):
        q_s = lie.quat_slerp(q, other / np.linalg.norm(other), 0.3)
        assert_allclose(q_s * np.sign(q_s @ q), q, rtol=0, atol=1e-13)


# ---------------------------------------------------------------------------------------------
# Random samples and validation
# ---------------------------------------------------------------------------------------------


def test_random_rotations_are_uniform(rng):
    R = tf.random_rotation(rng, size=4000)
    assert R.shape == (4000, 3, 3)
    assert all(tf.is_valid_T(make_pose(r, np.zeros(3)), atol=1e-12) for r in R[:50])
    # Haar measure: E[R] = 0 (entry std 1/sqrt(3), so the mean's std is 0.009) and the angle has
    # density (1 - cos(theta)) / pi on [0, pi], mean pi/2 + 2/pi (std of the mean 0.011)
    assert np.abs(R.mean(axis=0)).max() < 0.04
    mean_angle = np.radians(tf.rotation_angle_deg(R)).mean()
    assert mean_angle == pytest.approx(math.pi / 2 + 2 / math.pi, abs=0.05)


def test_random_pose_is_seeded_and_bounded(rng):
    Ts = tf.random_pose(rng, max_translation=0.5, size=500)
    assert np.linalg.norm(Ts[:, :3, 3], axis=1).max() <= 0.5
    assert np.linalg.norm(Ts[:, :3, 3], axis=1).max() > 0.45  # fills the ball
    assert tf.random_pose(7).shape == (4, 4)
    assert_allclose(tf.random_pose(7), tf.random_pose(np.random.default_rng(7)), atol=0)
    assert tf.is_valid_T(tf.random_pose(rng, max_translation=100.0))


def test_validation_of_rigid_transforms():
    T = make_pose(RZ90, [1.0, 2.0, 3.0])
    assert tf.is_valid_T(T)
    checked = tf.validate_T(T.tolist(), "T_camera_lidar")
    assert checked.dtype == np.float64 and checked.flags.c_contiguous
    assert_allclose(checked, T, atol=0)
    reflection = make_pose(np.diag([1.0, 1.0, -1.0]), np.zeros(3))
    scaled = make_pose(1.01 * RZ90, np.zeros(3))
    bad_row = T.copy()
    bad_row[3, 0] = 0.5
    with_nan = T.copy()
    with_nan[0, 3] = np.nan
    for bad in (reflection, scaled, bad_row, with_nan, T[:3], np.eye(3), "T"):
        assert not tf.is_valid_T(bad)
    with pytest.raises(ValueError, match=r"T_camera_lidar\[:3, :3\] is not a rotation.*det"):
        tf.validate_T(reflection, "T_camera_lidar")
    with pytest.raises(ValueError, match=r"last row"):
        tf.validate_T(bad_row)
    with pytest.raises(ValueError, match=r"item 1"):
        tf.validate_T(np.stack([T, scaled]), batch=True)
    assert tf.validate_rotation(RZ90).shape == (3, 3)
    with pytest.raises(ValueError, match=r"R_c is not a rotation"):
        tf.validate_rotation(2 * np.eye(3), "R_c")


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: tf.hat([1.0, 2.0]), r"omega must have shape \(3,\) or \(N, 3\), got \(2,\)"),
        (lambda: tf.vee(np.zeros((3, 4))), r"Omega must have shape \(3, 3\)"),
        (lambda: tf.so3_exp([np.nan, 0.0, 0.0]), r"omega must be finite"),
        (lambda: tf.so3_exp("abc"), r"omega must be an array of numbers"),
        (lambda: tf.so3_exp(np.zeros((2, 2, 3))), r"omega must have shape"),
        (lambda: tf.so3_log(2.0 * np.eye(3)), r"R is not a rotation"),
        (lambda: tf.se3_exp(np.zeros(5)), r"xi must have shape \(6,\) or \(N, 6\)"),
        (lambda: tf.se3_log(np.eye(3)), r"T must have shape \(4, 4\)"),
        (lambda: tf.make_T(np.eye(3), np.zeros(4)), r"t must have shape"),
        (lambda: tf.make_T(np.eye(3), np.zeros((2, 3))), r"R and t must"),
        (lambda: tf.make_T(np.ones((3, 3)), np.zeros(3)), r"R is not a rotation"),
        (lambda: tf.invert_T(np.diag([1.0, 1.0, -1.0, 1.0])), r"T\[:3, :3\] is not a rotation"),
        (lambda: tf.transform_points(np.eye(4), np.zeros((5, 2))), r"points_b must have shape"),
        (lambda: tf.transform_points(np.eye(4)[None], np.zeros(3)), r"T_a_b must have shape"),
        (lambda: tf.quat_xyzw_to_matrix(np.zeros(4)), r"q_xyzw has zero norm"),
        (lambda: tf.quat_xyzw_to_matrix([0.0, 0.0, 1.0]), r"q_xyzw must have shape \(4,\)"),
        (lambda: tf.pose_from_xyz_quat(np.zeros(7)), r"quaternion\) has zero norm"),
        (lambda: tf.pose_from_xyz_quat(np.zeros(6)), r"xyz_quat must have shape \(7,\)"),
        (lambda: tf.interpolate_pose(np.eye(4), np.eye(4), np.zeros((2, 2))), r"s must be"),
        (lambda: tf.interpolate_pose(np.eye(4), np.eye(4), np.nan), r"s must be finite"),
        (
            lambda: tf.interpolate_pose(np.eye(4), np.diag([2.0, 2.0, 2.0, 1.0]), 0.5),
            r"T_1\[:3, :3\]",
        ),
        (lambda: tf.slerp_rotation(np.eye(3), np.eye(3)[None], 0.5), r"R1 must have shape"),
        (lambda: tf.pose_error(np.eye(4), np.eye(4)[None]), r"same shape"),
        (lambda: tf.random_pose(0, max_translation=-1.0), r"max_translation"),
    ],
)
def test_bad_inputs_raise_value_error(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_offset_pose_is_exactly_the_asked_distance_and_angle_away():
    """offset_pose: exactly angle_deg and distance from the pose (pose_error of the camera
    poses), seeded by its generator (a generator continues its sequence, as several starts
    drawn from one generator need), and the report's restarts are made by it."""
    from nbcalib.report.uncertainty import RESTART_SEED, restart_starts
    from nbcalib.transforms import invert_T, offset_pose, pose_error, se3_exp

    T = se3_exp(np.array([0.1, -0.2, 0.3, 0.2, -0.1, 0.05]))
    gen = np.random.default_rng(7)
    first, second = offset_pose(T, 1.5, 0.07, gen), offset_pose(T, 1.5, 0.07, gen)
    for T0 in (first, second):
        dt, dr = pose_error(invert_T(T0), invert_T(T))
        assert dt == pytest.approx(0.07, abs=1e-12) and dr == pytest.approx(1.5, abs=1e-9)
    assert not np.array_equal(first, second)  # the generator went on
    np.testing.assert_array_equal(offset_pose(T, 1.5, 0.07, 7), first)  # a seed: a new one
    gen = np.random.default_rng(RESTART_SEED)
    made = [offset_pose(T, 1.0, 0.05, gen) for _ in range(3)]
    np.testing.assert_array_equal(np.array(restart_starts(T, 3, 0.05, 1.0)), np.array(made))
