"""The optimiser's chart: the closed-form SE(3) left Jacobian against finite differences."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.registration.optimize import se3_left_jacobian
from nbcalib.transforms import se3_exp, se3_log


def _left_jacobian_fd(xi, h=1e-7):
    """Central differences of ``log(exp(xi + h e_k) exp(xi)^-1)``: the definition."""
    T_inv = np.linalg.inv(se3_exp(xi))
    J = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = h
        J[:, k] = (se3_log(se3_exp(xi + e) @ T_inv) - se3_log(se3_exp(xi - e) @ T_inv)) / (2 * h)
    return J


@pytest.mark.parametrize("scale", [0.0, 1e-6, 1e-4, 9e-4, 1.1e-3, 0.05, 0.5, 2.0])
def test_se3_left_jacobian_matches_finite_differences(rng, scale):
    for _ in range(5):
        xi = rng.normal(size=6) * scale
        xi[:3] *= 3.0  # translations of metres next to rotations of radians
        # central differences with h = 1e-7: rounding ~1e-9, up to 2e-8 at 2-radian rotations
        assert_allclose(se3_left_jacobian(xi), _left_jacobian_fd(xi), rtol=0, atol=1e-7)


def test_se3_left_jacobian_at_zero_is_identity():
    assert_allclose(se3_left_jacobian(np.zeros(6)), np.eye(6), rtol=0, atol=0)
