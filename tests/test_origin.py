"""The LiDAR's origin in its clouds' frame (nbcalib.preprocess.origin), and where it is used."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from odometry_scene import cast, pattern

from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.origin import (
    MIN_OFFSET,
    LidarOrigin,
    choose_lidar_origin,
    find_lidar_origin,
    lidar_origin,
    ring_spread,
)


def scan(beams: int = 32, columns: int = 900, noise: float = 0.002, seed: int = 0) -> np.ndarray:
    """One sweep of a spinning LiDAR at rest in the analytic room, in its own frame."""
    d, _ = pattern(beams, columns)
    r = cast(np.zeros((len(d), 3)), d)
    r = r + np.random.default_rng(seed).normal(0.0, noise, len(r))
    return d * r[:, None]


def test_the_kernel_matches_its_reference():
    from nbcalib.kernels.origin import _ring_spreads
    from nbcalib.preprocess import origin as module
    from nbcalib.reference.origin import ring_spread as reference

    points = scan(beams=16, columns=300) + np.array([0.3, -0.2, 0.5])
    xs, ys, zs = np.array([0.0, 0.3]), np.array([-0.2, 0.4]), np.array([-0.5, 0.0, 0.5, 4.0])
    got = module.ring_spreads(points, xs, ys, zs)
    for i, j, k in np.ndindex(got.shape):
        expected = reference(
            points, (xs[i], ys[j], zs[k]), width=module._WIDTH, group=module._GROUP,
            u_max=module._U_MAX, min_distance=module._MIN_DISTANCE,
        )  # fmt: skip
        assert got[i, j, k] == pytest.approx(expected, abs=1e-12)
    assert _ring_spreads.__module__ == "nbcalib.kernels.origin"


def test_rings_are_sharpest_from_the_sensor():
    points = scan()
    here = ring_spread(points)
    assert here < 0.2  # every beam one elevation: the fine bins add almost nothing
    for offset in ([0.0, 0.0, 1.5], [1.0, -0.5, 0.0]):
        assert ring_spread(points, offset) > here + 0.3


@pytest.mark.parametrize("offset", [(1.2, -0.3, 2.0), (-0.8, 0.9, 1.1)])
def test_the_origin_of_a_cloud_in_another_frame_is_found(offset):
    # the scan in a "vehicle frame" whose origin lies below and beside the LiDAR
    o = np.array(offset)
    points = scan() + o
    found, spread, at_zero, edge = find_lidar_origin(points)
    assert not edge
    assert np.linalg.norm(found - o) < 0.12
    assert spread < 0.5 * at_zero
    chosen = choose_lidar_origin([points, scan(seed=1) + o])
    assert chosen.source == "found" and chosen.moved
    assert np.linalg.norm(np.array(chosen.xyz) - o) < 0.12
    assert "found" in chosen.describe() and "m in the cloud's frame" in chosen.describe()


def test_a_cloud_centred_on_its_sensor_keeps_its_origin():
    chosen = choose_lidar_origin([scan()])
    assert chosen == LidarOrigin(detail=chosen.detail) and not chosen.moved
    # found a little off (the sensor's own geometry): not moved, MIN_OFFSET away at least
    near = choose_lidar_origin([scan() + np.array([0.0, 0.0, 0.6 * MIN_OFFSET])])
    assert not near.moved


def test_a_scan_without_rings_is_not_searched():
    rng = np.random.default_rng(3)
    d = rng.normal(size=(20000, 3))
    d[:, 0] = np.abs(d[:, 0]) + 2.0  # a forward-looking, non-repetitive pattern: ~70 degrees
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    points = d * cast(np.zeros((len(d), 3)), d)[:, None]
    chosen = choose_lidar_origin([points + np.array([0.0, 0.0, 2.0])])
    assert not chosen.moved and "not a spinning" in chosen.detail


def test_scans_that_disagree_keep_the_origin():
    a, b = scan() + np.array([1.5, 0.0, 2.0]), scan(seed=1) + np.array([-1.5, 1.0, 0.5])
    chosen = choose_lidar_origin([a, b])
    assert not chosen.moved and "not at one place" in chosen.detail


def test_the_setting_takes_words_or_three_numbers():
    assert PreprocessConfig().lidar_origin == "auto"
    assert PreprocessConfig(lidar_origin="1, 2.5, -3").given_origin() == (1.0, 2.5, -3.0)
    assert PreprocessConfig(lidar_origin="cloud").given_origin() is None
    for bad in ("1,2", "somewhere", "1,2,nan"):
        with pytest.raises(ValueError, match="lidar_origin"):
            PreprocessConfig(lidar_origin=bad)


class _Pair:
    def __init__(self, points):
        self.scans = [type("Scan", (), {"points": points})()]
        self.image_scan = None


def test_lidar_origin_follows_the_setting():
    pairs = [_Pair(scan() + np.array([1.2, -0.3, 2.0]))]
    assert lidar_origin(pairs, PreprocessConfig(lidar_origin="cloud")).xyz == (0.0, 0.0, 0.0)
    given = lidar_origin(pairs, PreprocessConfig(lidar_origin="1,2,3"))
    assert given.xyz == (1.0, 2.0, 3.0) and given.source == "given"
    found = lidar_origin(pairs, PreprocessConfig())
    assert found.source == "found"


def test_the_guess_is_the_same_seen_from_the_origin():
    """Shifting the points and naming the shift as the origin moves the answer by the shift."""
    from nbcalib.camera import example_camera
    from nbcalib.initial_guess import estimate_initial_guess, synthetic_correspondences
    from nbcalib.synthetic import default_T_camera_lidar
    from nbcalib.transforms import make_T

    camera = example_camera("plumb_bob")
    truth = default_T_camera_lidar("spinning", 0)
    c = synthetic_correspondences(camera, truth, 0, n_inliers=80, outlier_fraction=0.7)
    plain = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, seed=0)
    # an origin at zero is no origin: the same numbers
    zero = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, seed=0, origin=[0, 0, 0])
    assert np.array_equal(zero.T_camera_lidar, plain.T_camera_lidar)
    o = np.array([1.3, -0.2, 2.1])
    shifted = estimate_initial_guess(camera, c.uv_camera, c.points_lidar + o, seed=0, origin=o)
    expected = plain.T_camera_lidar @ make_T(np.eye(3), -o)
    assert_allclose(shifted.T_camera_lidar, expected, atol=1e-6)
    assert shifted.n_inliers == plain.n_inliers and shifted.success == plain.success
    # without the origin, rotation-only RANSAC sees the points from 2.5 m away
    assert estimate_initial_guess(camera, c.uv_camera, c.points_lidar + o, seed=0) is not None
