"""Hypothesis strategies shared by the tests: rotations, poses, quaternions, point clouds.

Samples are built with NumPy and SciPy only, never with the nbcalib code they test. Rotation
angles come from three families, so that every branch of the exp/log formulas is exercised:
uniform in [0, pi), near the identity (down to 1e-12 rad) and near pi (down to pi - 1e-9).
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp
from scipy.spatial.transform import Rotation

#: the closest approach to pi of the "near pi" angles: closer, the sign of the rotation vector
#: (+pi a or -pi a, the same rotation) is no longer determined by the matrix in float64
NEAR_PI_MIN_GAP = 1e-9


def _finite(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False, allow_subnormal=False)


@st.composite
def unit_vectors(draw) -> np.ndarray:
    """Directions (3,) uniform on the unit sphere (uniform height z and azimuth)."""
    z = draw(_finite(-1.0, 1.0))
    phi = draw(_finite(0.0, 2.0 * math.pi))
    r = math.sqrt(max(0.0, 1.0 - z * z))
    return np.array([r * math.cos(phi), r * math.sin(phi), z])


def rotation_angles() -> st.SearchStrategy[float]:
    """Angles in [0, pi): 0, uniform, near the identity and near pi (radians)."""
    return st.one_of(
        st.just(0.0),
        st.floats(0.0, math.pi, exclude_max=True, allow_subnormal=False),
        _finite(-12.0, -3.0).map(lambda e: 10.0**e),
        _finite(math.log10(NEAR_PI_MIN_GAP), -1.0).map(lambda e: math.pi - 10.0**e),
    )


def rotation_vectors() -> st.SearchStrategy[np.ndarray]:
    """Rotation vectors (3,) with angle in [0, pi) (see :func:`rotation_angles`)."""
    return st.builds(lambda axis, angle: axis * angle, unit_vectors(), rotation_angles())


def rotation_matrices() -> st.SearchStrategy[np.ndarray]:
    """Rotation matrices (3, 3) of :func:`rotation_vectors`, made by SciPy."""
    return rotation_vectors().map(lambda w: Rotation.from_rotvec(w).as_matrix())


def translations(max_abs: float = 10.0) -> st.SearchStrategy[np.ndarray]:
    """Translations (3,) with components in [-max_abs, max_abs] metres."""
    return hnp.arrays(np.float64, 3, elements=_finite(-max_abs, max_abs))


def se3_tangents() -> st.SearchStrategy[np.ndarray]:
    """Tangent vectors (6,) ``[v, omega]``, |v_i| <= 10 m and rotation angle in [0, pi)."""
    return st.builds(lambda v, w: np.concatenate([v, w]), translations(), rotation_vectors())


def poses() -> st.SearchStrategy[np.ndarray]:
    """Rigid transforms (4, 4) with rotations of :func:`rotation_matrices`."""

    def make(R: np.ndarray, t: np.ndarray) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        return T

    return st.builds(make, rotation_matrices(), translations())


def unit_quaternions() -> st.SearchStrategy[np.ndarray]:
    """Unit quaternions (4,) xyzw of either sign: ``[sin(a/2) axis, cos(a/2)]`` or its negative."""

    def make(axis: np.ndarray, angle: float, sign: float) -> np.ndarray:
        return sign * np.append(math.sin(0.5 * angle) * axis, math.cos(0.5 * angle))

    return st.builds(make, unit_vectors(), rotation_angles(), st.sampled_from([1.0, -1.0]))


def point_clouds(max_points: int = 16, max_abs: float = 100.0) -> st.SearchStrategy[np.ndarray]:
    """Point arrays (N, 3), 0 <= N <= max_points, coordinates in [-max_abs, max_abs] metres."""
    shape = st.tuples(st.integers(0, max_points), st.just(3))
    return hnp.arrays(np.float64, shape, elements=_finite(-max_abs, max_abs))


def fractions() -> st.SearchStrategy[float]:
    """Interpolation fractions in [0, 1]."""
    return _finite(0.0, 1.0)
