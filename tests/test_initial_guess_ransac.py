"""Rotation-only RANSAC: random streams, Kabsch, kernel == reference, determinism, wrapper."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.camera import create_camera, example_camera
from nbcalib.errors import InputError
from nbcalib.initial_guess.ransac import estimate_rotation_ransac, usable_correspondences
from nbcalib.kernels import ransac as K
from nbcalib.reference import ransac as ref
from nbcalib.transforms import random_rotation, rotation_angle_deg
from tests.tolerances import TOL

ROOT = Path(__file__).resolve().parents[1]


def _bearings_problem(camera, rng, m=60, inlier_fraction=0.4, noise_px=0.3):
    """Far-field correspondences: LiDAR bearings = R^T camera bearings for the inliers."""
    uv = rng.uniform([0, 0], [camera.width - 1, camera.height - 1], (m, 2))
    bc = camera.unproject(uv)
    keep = np.all(np.isfinite(bc), axis=1)
    uv, bc = uv[keep], bc[keep]
    R = random_rotation(rng)
    bl = bc @ R  # rows R^T c
    n_out = round(len(uv) * (1 - inlier_fraction))
    out = rng.normal(size=(n_out, 3))
    bl[:n_out] = out / np.linalg.norm(out, axis=1, keepdims=True)
    uv_obs = uv + rng.normal(0, noise_px, uv.shape)
    return np.ascontiguousarray(bc), np.ascontiguousarray(bl), uv_obs, R, n_out


def test_draws_are_splitmix64():
    # first outputs of SplitMix64 seeded with 0 (Vigna's reference implementation)
    assert ref.draw(0, 0) == 0xE220A8397B1DCDAF
    assert ref.draw(0, 1) == 0x6E789E6AA1B965F4
    for seed in (0, 1, 12345, 2**63 + 7, 2**64 - 1):
        for k in (0, 1, 2, 1000, 2**40):
            assert int(K._draw(np.uint64(seed), k)) == ref.draw(seed, k)


@pytest.mark.parametrize("m", [2, 3, 7, 1000])
def test_sample_pairs_are_distinct_in_range_and_match_the_reference(m):
    key = np.uint64(99)
    pairs = [K._sample_pair(key, i, m) for i in range(500)]
    assert pairs == [ref.sample_pair(99, i, m) for i in range(500)]
    j0, j1 = np.array(pairs).T
    assert np.all(j0 != j1) and j0.min() >= 0 and j1.min() >= 0
    assert j0.max() < m and j1.max() < m
    if m == 3:  # every ordered pair of distinct indices appears
        assert len(set(pairs)) == 6


def test_kabsch_rotation_of_two_consistent_pairs_is_exact(rng):
    for _ in range(50):
        R = random_rotation(rng)
        bl = rng.normal(size=(2, 3))
        bl /= np.linalg.norm(bl, axis=1, keepdims=True)
        bc = bl @ R.T
        R_k = K._rotation_from_pair(bc, bl, 0, 1)
        assert_allclose(R_k, R, **TOL["kabsch_rotation"])
        assert_allclose(R_k, ref.rotation_from_pair(bc[0], bc[1], bl[0], bl[1]), atol=1e-12)
        assert np.linalg.det(R_k) == pytest.approx(1.0, abs=1e-12)


def test_kabsch_never_returns_a_reflection(rng):
    # inconsistent pairs (different angles between the bearings): still a proper rotation
    for _ in range(200):
        b = rng.normal(size=(4, 3))
        b /= np.linalg.norm(b, axis=1, keepdims=True)
        R = K._rotation_from_pair(b[:2], b[2:], 0, 1)
        assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0, abs=1e-12)


@pytest.mark.parametrize("model", ["pinhole", "fisheye", "omnidir", "equirectangular"])
def test_kernel_counts_equal_the_reference_exactly(model, rng):
    camera = example_camera(model, 320, 240)
    bc, bl, uv, _, _ = _bearings_problem(camera, rng, m=40)
    bl[0] = -bc[0]  # a correspondence pointing behind the camera for most hypotheses
    threshold, iterations, seed = 4.0, 150, 2024
    expected = ref.hypothesis_counts(
        camera.model_id, camera.params, bc, bl, uv, threshold, iterations, seed
    )
    for kernel in (K._hypothesis_counts, K._hypothesis_counts_parallel):
        counts = np.full(iterations, -7, dtype=np.int64)
        kernel(camera.model_id, camera.params, bc, bl, uv, threshold**2, np.uint64(seed), counts)
        assert np.array_equal(counts, expected)
    best, best_count, R_ref = ref.rotation_ransac(
        camera.model_id, camera.params, bc, bl, uv, threshold, iterations, seed
    )
    assert best == int(np.argmax(expected)) and best_count == expected.max()
    R = K._rotation_of_iteration(bc, bl, np.uint64(seed), best)
    assert_allclose(R, R_ref, **TOL["kernel_vs_reference"])
    mask = np.zeros(len(bl), dtype=np.bool_)
    K._inlier_mask(camera.model_id, camera.params, R, bl, uv, threshold**2, mask)
    assert np.array_equal(
        mask, ref.inlier_mask(camera.model_id, camera.params, R, bl, uv, threshold)
    )


def test_parallel_equals_serial_on_any_thread_count(rng):
    camera = example_camera("plumb_bob", 640, 480)
    bc, bl, uv, _, _ = _bearings_problem(camera, rng, m=300, inlier_fraction=0.2)
    iterations = 3 * K.BLOCK_SIZE + 5  # a partial last block
    serial = np.empty(iterations, dtype=np.int64)
    K._hypothesis_counts(camera.model_id, camera.params, bc, bl, uv, 9.0, np.uint64(5), serial)
    default_threads = numba.get_num_threads()
    try:
        for threads in sorted({1, default_threads}):
            numba.set_num_threads(threads)
            for _ in range(3):
                counts = np.empty(iterations, dtype=np.int64)
                K._hypothesis_counts_parallel(
                    camera.model_id, camera.params, bc, bl, uv, 9.0, np.uint64(5), counts
                )
                assert np.array_equal(counts, serial)
    finally:
        numba.set_num_threads(default_threads)


@pytest.mark.slow
def test_result_is_the_same_with_more_threads_than_cores():
    code = (
        "import numpy as np\n"
        "from nbcalib.camera import example_camera\n"
        "from nbcalib.initial_guess import estimate_rotation_ransac, synthetic_correspondences\n"
        "from nbcalib.synthetic import default_T_camera_lidar\n"
        "cam = example_camera('fisheye')\n"
        "c = synthetic_correspondences(cam, default_T_camera_lidar('spinning', 1), 1,\n"
        "                              n_inliers=80, outlier_fraction=0.85)\n"
        "r = estimate_rotation_ransac(cam, c.uv_camera, c.points_lidar, iterations=2000, seed=9)\n"
        "print(r.best_iteration, int(r.counts.sum()), r.R_camera_lidar.tobytes().hex())\n"
    )
    outputs = set()
    for threads in ("1", "2", "7"):
        env = {**os.environ, "NUMBA_NUM_THREADS": threads}
        out = subprocess.run(
            [sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True
        )
        assert out.returncode == 0, out.stderr
        outputs.add(out.stdout)
    assert len(outputs) == 1


@pytest.mark.parametrize("model", ["pinhole", "fisheye", "equirectangular"])
def test_wrapper_finds_the_rotation_with_many_outliers(model, rng):
    camera = example_camera(model, 640, 480)
    _bc, bl, uv, R, n_out = _bearings_problem(camera, rng, m=200, inlier_fraction=0.2)
    points = bl * rng.uniform(20.0, 60.0, (len(bl), 1))  # far field
    result = estimate_rotation_ransac(camera, uv, points, iterations=2000, threshold=3.0, seed=1)
    assert rotation_angle_deg(result.R_camera_lidar @ R.T) < 0.3
    assert result.inliers[n_out:].mean() > 0.9 and result.inliers[:n_out].mean() < 0.05
    assert result.counts.shape == (2000,) and result.best_iteration == np.argmax(result.counts)
    assert result.n_inliers == result.counts.max()


def test_seed_iterations_and_threshold_are_honoured(rng):
    camera = example_camera("plumb_bob", 640, 480)
    _bc, bl, uv, _, _ = _bearings_problem(camera, rng, m=150, inlier_fraction=0.3)
    a = estimate_rotation_ransac(camera, uv, bl, iterations=777, seed=3)
    b = estimate_rotation_ransac(camera, uv, bl, iterations=777, seed=3, parallel=False)
    c = estimate_rotation_ransac(camera, uv, bl, iterations=777, seed=4)
    assert a.iterations == 777 and a.counts.shape == (777,)
    assert np.array_equal(a.counts, b.counts) and a.best_iteration == b.best_iteration
    assert np.array_equal(a.R_camera_lidar, b.R_camera_lidar)
    assert not np.array_equal(a.counts, c.counts)
    # the first 100 iterations of a longer run are the same hypotheses
    short = estimate_rotation_ransac(camera, uv, bl, iterations=100, seed=3)
    assert np.array_equal(short.counts, a.counts[:100])
    wide = estimate_rotation_ransac(camera, uv, bl, iterations=777, seed=3, threshold=20.0)
    assert np.all(wide.counts >= a.counts) and wide.threshold == 20.0
    # every reported inlier is within the threshold for the winning rotation
    proj, valid = camera.project(bl[a.inliers] @ a.R_camera_lidar.T)
    assert valid.all() and np.all(np.linalg.norm(proj - uv[a.inliers], axis=1) < 5.0)


def test_ranked_hypotheses_are_distinct_and_start_with_the_winner(rng):
    camera = example_camera("pinhole", 640, 480)
    _bc, bl, uv, _, _ = _bearings_problem(camera, rng, m=120, inlier_fraction=0.3)
    result = estimate_rotation_ransac(camera, uv, bl, iterations=500, seed=2)
    ranked = result.ranked_hypotheses(6, min_separation_deg=2.0)
    assert ranked[0][0] == result.best_iteration
    assert_allclose(ranked[0][2], result.R_camera_lidar, atol=0)
    counts = [c for _, c, _ in ranked]
    assert counts == sorted(counts, reverse=True)
    for i in range(len(ranked)):
        for j in range(i):
            assert rotation_angle_deg(ranked[i][2] @ ranked[j][2].T) >= 2.0
    assert np.array_equal(result.inlier_mask(result.R_camera_lidar), result.inliers)


def test_unusable_correspondences_are_skipped_not_fatal(rng):
    camera = create_camera("fisheye", [200, 200, 319.5, 239.5], [0.4, 0.0, 0.0, 0.0], 640, 480)
    uv = rng.uniform([0, 0], [639, 479], (40, 2))
    points = camera.unproject(uv) * 10.0
    uv[0] = [-5000.0, 0.0]  # outside the fisheye's monotonic domain: NaN bearing
    points[1] = 0.0  # the LiDAR origin has no bearing
    _bc, _bl, usable = usable_correspondences(camera, uv, points)
    assert not usable[0] and not usable[1] and usable[2:].all()
    result = estimate_rotation_ransac(camera, uv, points, iterations=200, seed=0)
    assert not result.inliers[:2].any() and result.inliers[2:].all()
    assert rotation_angle_deg(result.R_camera_lidar) < 1e-6


def test_bad_inputs():
    camera = example_camera("pinhole", 64, 48)
    with pytest.raises(InputError, match="too few"):
        estimate_rotation_ransac(camera, [[1.0, 2.0]], [[1.0, 0.0, 5.0]])
    with pytest.raises(ValueError, match="shape"):
        estimate_rotation_ransac(camera, np.zeros((3, 3)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="finite"):
        estimate_rotation_ransac(camera, [[np.nan, 0.0]] * 3, np.ones((3, 3)))
    with pytest.raises(ValueError, match="iterations"):
        estimate_rotation_ransac(camera, np.zeros((3, 2)), np.ones((3, 3)), iterations=0)
    with pytest.raises(ValueError, match="threshold"):
        estimate_rotation_ransac(camera, np.zeros((3, 2)), np.ones((3, 3)), threshold=-1.0)
    with pytest.raises(ValueError, match="seed"):
        estimate_rotation_ransac(camera, np.zeros((3, 2)), np.ones((3, 3)), seed=-1)
