"""Rotation-only RANSAC kernels (paper Algorithm 1), deterministic for a seed on any thread count.

Semantics (shared with the slow reference :mod:`nbcalib.reference.ransac`):

- Input: ``M >= 2`` correspondences, each a unit camera bearing ``bearings_camera[j]`` (the
  unprojected keypoint), a unit LiDAR bearing ``bearings_lidar[j]`` (the normalised 3-D point:
  far-field assumption, translation ignored) and the keypoint's pixel ``uv[j]``.
- **Random numbers**: one SplitMix64 sequence per seed, used *counter-based*: draw ``k`` is
  ``mix64(key + (k + 1) * 0x9E3779B97F4A7C15)`` with ``key = seed mod 2**64``. Iteration ``i``
  uses draws ``2 i`` and ``2 i + 1``, so any block of iterations can start its own stream at its
  first iteration, and the result does not depend on how iterations are split among threads.
- **Sample**: ``j0 = floor(x0 M)`` and ``j1 = (j0 + 1 + floor(x1 (M - 1))) mod M`` with ``x`` the
  top 53 bits of a draw as a float in [0, 1): two *distinct* correspondences, uniformly (the
  reference toolbox draws with replacement, and a repeated index gives a degenerate rotation).
- **Rotation** (``FINDROTATIONLSQ``, Kabsch / Umeyama): ``H = c0 l0^T + c1 l1^T``, ``H = U S V^T``
  (``numpy.linalg.svd``), ``s = sign(det U det V)`` (+1 when the product is 0), ``R = U diag(1,
  1, s) V^T``: the rotation with ``R l ~ c`` (``R_camera_lidar``).
- **Inliers**: ``R l_j`` is projected through the camera with
  :func:`nbcalib.kernels.projection.project_point`; correspondence ``j`` is an inlier when the
  projection is valid and ``du^2 + dv^2 < threshold^2``. Points that the rotation sends behind the
  camera (or outside the model's domain) are outliers.
- **Best**: most inliers; on equal counts the lowest iteration index wins (``np.argmax`` of the
  per-iteration counts), so the answer is one iteration's rotation, reproducible from
  ``(seed, i)`` with :func:`_rotation_of_iteration`.

Parallelism: :func:`_hypothesis_counts` writes the inlier count of every iteration into its own
slot of an array; :func:`_hypothesis_counts_parallel` is the same function compiled with
``prange`` over blocks of :data:`BLOCK_SIZE` iterations. Since each iteration's random numbers
and result depend only on ``(seed, i)``, the two give identical arrays on any number of threads.
Keeping every count (8 bytes per iteration) also lets the caller rank the hypotheses.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_parallel
from nbcalib.kernels.projection import project_point

#: Iterations per parallel work item.
BLOCK_SIZE = 64

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX1 = np.uint64(0xBF58476D1CE4E5B9)
_MIX2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_TWO_POW_M53 = 1.0 / 9007199254740992.0  # 2**-53


@jit
def _draw(key, k):
    """Draw ``k`` (>= 0) of the SplitMix64 sequence of ``key``, as a uint64."""
    z = key + np.uint64(k + 1) * _GOLDEN
    z = (z ^ (z >> _S30)) * _MIX1
    z = (z ^ (z >> _S27)) * _MIX2
    return z ^ (z >> _S31)


@jit
def _uniform_index(z, m):
    """``floor(x m)`` for the top 53 bits ``x`` of ``z`` as a float in [0, 1); in [0, m)."""
    x = np.float64(z >> _S11) * _TWO_POW_M53
    j = np.int64(np.floor(x * m))
    return min(j, m - 1)


@jit
def _sample_pair(key, i, m):
    """The two distinct correspondence indices of iteration ``i`` (``m >= 2``)."""
    j0 = _uniform_index(_draw(key, 2 * i), m)
    j1 = (j0 + 1 + _uniform_index(_draw(key, 2 * i + 1), m - 1)) % m
    return j0, j1


@jit
def _det3(A):
    return (
        A[0, 0] * (A[1, 1] * A[2, 2] - A[1, 2] * A[2, 1])
        - A[0, 1] * (A[1, 0] * A[2, 2] - A[1, 2] * A[2, 0])
        + A[0, 2] * (A[1, 0] * A[2, 1] - A[1, 1] * A[2, 0])
    )


@jit
def _rotation_from_pair(bearings_camera, bearings_lidar, j0, j1):
    """Kabsch rotation ``R`` (3 x 3) with ``R l ~ c`` for correspondences ``j0``, ``j1``."""
    H = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            H[a, b] = (
                bearings_camera[j0, a] * bearings_lidar[j0, b]
                + bearings_camera[j1, a] * bearings_lidar[j1, b]
            )
    U, _, Vt = np.linalg.svd(H)
    s = 1.0 if _det3(U) * _det3(Vt) >= 0.0 else -1.0
    R = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            R[a, b] = U[a, 0] * Vt[0, b] + U[a, 1] * Vt[1, b] + s * U[a, 2] * Vt[2, b]
    return R


@jit
def _is_inlier(model_id, params, R, bearing_lidar, u_obs, v_obs, threshold2):
    """Whether ``R l`` projects within ``sqrt(threshold2)`` pixels of ``(u_obs, v_obs)``."""
    lx = bearing_lidar[0]
    ly = bearing_lidar[1]
    lz = bearing_lidar[2]
    X = R[0, 0] * lx + R[0, 1] * ly + R[0, 2] * lz
    Y = R[1, 0] * lx + R[1, 1] * ly + R[1, 2] * lz
    Z = R[2, 0] * lx + R[2, 1] * ly + R[2, 2] * lz
    u, v, ok = project_point(model_id, params, X, Y, Z)
    if not ok:
        return False
    du = u - u_obs
    dv = v - v_obs
    return du * du + dv * dv < threshold2


@jit
def _count_inliers(model_id, params, R, bearings_lidar, uv, threshold2):
    n = 0
    for j in range(bearings_lidar.shape[0]):
        if _is_inlier(model_id, params, R, bearings_lidar[j], uv[j, 0], uv[j, 1], threshold2):
            n += 1
    return n


@jit
def _inlier_mask(model_id, params, R, bearings_lidar, uv, threshold2, out):
    """Write the inlier flags of rotation ``R`` into ``out`` (bool, shape (M,))."""
    for j in range(bearings_lidar.shape[0]):
        out[j] = _is_inlier(model_id, params, R, bearings_lidar[j], uv[j, 0], uv[j, 1], threshold2)


@jit
def _rotation_of_iteration(bearings_camera, bearings_lidar, key, i):
    """The rotation hypothesis of iteration ``i`` (recomputed from the seed)."""
    j0, j1 = _sample_pair(key, i, bearings_camera.shape[0])
    return _rotation_from_pair(bearings_camera, bearings_lidar, j0, j1)


def _hypothesis_counts_impl(
    model_id, params, bearings_camera, bearings_lidar, uv, threshold2, key, counts
):
    m = bearings_camera.shape[0]
    iterations = counts.shape[0]
    n_blocks = (iterations + BLOCK_SIZE - 1) // BLOCK_SIZE
    for b in prange(n_blocks):
        stop = min(iterations, (b + 1) * BLOCK_SIZE)
        for i in range(b * BLOCK_SIZE, stop):
            j0, j1 = _sample_pair(key, i, m)
            R = _rotation_from_pair(bearings_camera, bearings_lidar, j0, j1)
            counts[i] = _count_inliers(model_id, params, R, bearings_lidar, uv, threshold2)


#: Inlier count of every hypothesis, serial: writes ``counts[i]`` (int64, shape (iterations,))
#: for iteration ``i``. Arguments: ``model_id`` (int), ``params`` (16,) float64,
#: ``bearings_camera`` / ``bearings_lidar`` (M, 3) unit float64 (``M >= 2``), ``uv`` (M, 2)
#: float64, ``threshold2`` (pixels squared), ``key`` (uint64 seed), ``counts``. The best
#: hypothesis is the first maximum, ``np.argmax(counts)``.
_hypothesis_counts = jit(_hypothesis_counts_impl)


#: The same function compiled with ``prange`` over blocks of iterations (identical output: each
#: iteration writes only its own slot).
_hypothesis_counts_parallel = jit_parallel(_hypothesis_counts_impl)
