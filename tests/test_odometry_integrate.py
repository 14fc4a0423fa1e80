"""Dense clouds by continuous-time ICP (integrate_dynamic) on the analytic scene and on KITTI.

The analytic scene (tests/odometry_scene.py) is scanned by a spinning LiDAR that moves at constant
velocity, for which the pose interpolation of the method (slerp + lerp) is exact: the ground truth
is known to rounding.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from odometry_scene import (
    SCAN_PERIOD,
    at_rest,
    make_sequence,
    rest_then_accelerate,
    scene_distance,
)

from nbcalib.errors import InputError
from nbcalib.odometry import (
    DynamicIntegrationConfig,
    integrate_dynamic,
    synthesize_times_from_azimuth,
)
from nbcalib.preprocess.accumulate import integrate_static
from nbcalib.transforms import interpolate_pose, pose_error, transform_points


@pytest.fixture(scope="module")
def sequence():
    return make_sequence(6)


@pytest.fixture(scope="module")
def dynamic_cloud(sequence):
    scans, times, _ = sequence
    return integrate_dynamic(scans, times)


# ---------------------------------------------------------------------------------------------
# Dynamic integration on the analytic scene
# ---------------------------------------------------------------------------------------------


def test_dynamic_recovers_constant_velocity_motion(sequence, dynamic_cloud):
    _, _, truth = sequence
    T_b_true = np.stack([b for b, _ in truth])
    T_e_true = np.stack([e for _, e in truth])
    tb, rb = pose_error(dynamic_cloud.T_first_scanbegin, T_b_true)
    te, re = pose_error(dynamic_cloud.T_first_scanend, T_e_true)
    assert np.array_equal(dynamic_cloud.T_first_scanbegin[0], np.eye(4))
    assert rb.max() < 0.1 and re.max() < 0.1, (rb, re)  # degrees
    assert tb.max() < 0.01 and te.max() < 0.01, (tb, te)  # metres
    assert dynamic_cloud.stats["registered"].all()


def test_first_scan_at_rest_is_not_deskewed_with_the_second_scans_motion():
    """Still during the first scan, then accelerating: the rigid bootstrap of the first scan's
    motion (constant velocity) would give it part of the second scan's motion and distort the
    map; the second scan's own registration says it begins at rest."""
    scans, times, truth = make_sequence(5, motion=rest_then_accelerate)
    cloud = integrate_dynamic(scans, times)
    assert np.array_equal(cloud.T_first_scanend[0], np.eye(4))
    T_e_true = np.stack([e for _, e in truth])
    te, re = pose_error(cloud.T_first_scanend, T_e_true)
    # slerp + lerp cannot follow an acceleration within a scan: up to ~0.29 degree here (alpha
    # T^2 / 8); the constant-velocity bootstrap gave 7 mm / 0.17 degree at the first scan's end
    # and 0.43 degree at the others
    assert te.max() < 0.012 and re.max() < 0.33, (te, re)  # metres, degrees


def test_moving_first_scan_is_deskewed(sequence, dynamic_cloud):
    """At constant velocity from the start, the first scan's end pose is the motion over it."""
    _, _, truth = sequence
    te, re = pose_error(dynamic_cloud.T_first_scanend[:1], truth[0][1][None])
    assert np.linalg.norm(truth[0][1][:3, 3]) > 0.1  # it did move
    assert te[0] < 0.005 and re[0] < 0.05, (te, re)


def test_narrow_kernel_removes_the_bias_at_rest():
    """A LiDAR at rest, 3 mm range noise: with the kernel narrowed to the noise the poses stay
    closer to rest than with a fixed 10 cm kernel, which lets points matched to the wrong
    surface (box edges) pull them."""
    scans, times, _ = make_sequence(6, motion=at_rest)

    def worst(config):
        cloud = integrate_dynamic(scans, times, config=config)
        eye = np.broadcast_to(np.eye(4), cloud.T_first_scanend.shape)
        tb, rb = pose_error(cloud.T_first_scanbegin, eye)
        te, re = pose_error(cloud.T_first_scanend, eye)
        return max(tb.max(), te.max()), max(rb.max(), re.max())

    narrow_t, narrow_r = worst(DynamicIntegrationConfig())
    _, wide_r = worst(DynamicIntegrationConfig(robust_sigmas=0.0))
    # measured: narrow 1.8 mm / 0.015 degree, wide 1.8 mm / 0.020 degree (the worst pose is a
    # scan's end, whose translation within the scan is the weakly observed part)
    assert narrow_t < 0.003 and narrow_r < 0.02, (narrow_t, narrow_r)
    assert narrow_r < wide_r, (narrow_r, wide_r)


def test_deskewed_cloud_is_sharper_than_raw(sequence, dynamic_cloud):
    """RMS distance to the known planes: deskewed accumulation < rigid per-scan accumulation."""
    scans, _, _ = sequence
    deskewed = np.sqrt(np.mean(scene_distance(dynamic_cloud.points) ** 2))
    raw = []
    for scan, T_b, T_e in zip(
        scans, dynamic_cloud.T_first_scanbegin, dynamic_cloud.T_first_scanend
    ):
        raw.append(transform_points(interpolate_pose(T_b, T_e, 0.5), scan[:, :3]))
    raw_rms = np.sqrt(np.mean(scene_distance(np.vstack(raw)) ** 2))
    assert deskewed < 0.01  # range noise is 3 mm
    assert deskewed < 0.5 * raw_rms, (deskewed, raw_rms)


def test_dynamic_is_deterministic(sequence, dynamic_cloud):
    scans, times, _ = sequence
    again = integrate_dynamic(
        scans[:4],
        times[:4],
        config=DynamicIntegrationConfig(background_accumulation=False, threads=1, parallel=True),
    )
    first = integrate_dynamic(scans[:4], times[:4])
    assert np.array_equal(first.points, again.points)
    assert np.array_equal(first.intensity, again.intensity)
    assert np.array_equal(first.T_first_scanend, again.T_first_scanend)
    assert np.array_equal(first.T_first_scanend, dynamic_cloud.T_first_scanend[:4])


def test_dynamic_uses_scan_times_and_reports_progress(sequence):
    scans, times, _ = sequence
    calls = []
    cloud = integrate_dynamic(
        [s[:, :3] for s in scans[:3]],
        times[:3],
        progress=lambda done, total: calls.append((done, total)),
    )
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert np.all(cloud.intensity == 0.0)
    # without times, they are synthesised from the azimuth (the same here)
    no_times = integrate_dynamic(
        [s[:, :3] for s in scans[:3]],
        frame_rate=1 / SCAN_PERIOD,
    )
    assert_allclose(no_times.T_first_scanend, cloud.T_first_scanend, atol=1e-6)


def test_dynamic_single_scan_and_empty_scans(sequence):
    scans, times, _ = sequence
    empty = np.zeros((0, 4))
    cloud = integrate_dynamic([empty, scans[0], empty], [np.zeros(0), times[0], np.zeros(0)])
    assert cloud.stats["registered"].tolist() == [False, True, False]
    assert cloud.stats["points_used"][1] > 0
    assert np.array_equal(cloud.T_first_scanend[1], np.eye(4))
    single = integrate_static([scans[0]], voxel_size=0.002)
    assert len(cloud) == len(single)


# ---------------------------------------------------------------------------------------------
# Bad input
# ---------------------------------------------------------------------------------------------


def test_bad_input_raises_clear_errors(sequence):
    scans, times, _ = sequence
    nan_scan = np.full((50, 4), np.nan)
    with pytest.raises(InputError, match="no scans"):
        integrate_dynamic([])
    with pytest.raises(InputError, match="no finite point"):
        integrate_dynamic([nan_scan])
    with pytest.raises(ValueError, match="times has 1 entries for 2 scans"):
        integrate_dynamic(scans[:2], times[:1])
    with pytest.raises(ValueError, match=r"scan 1: .* point times for"):
        integrate_dynamic(scans[:2], [times[0], times[1][:-1]])
    with pytest.raises(ValueError, match=r"shape \(N, 3\) or \(N, 4\)"):
        integrate_dynamic([np.zeros((5, 2))])
    with pytest.raises(ValueError, match="dedup"):
        DynamicIntegrationConfig(dedup="median")
    with pytest.raises(ValueError, match="max_correspondence_distance"):
        DynamicIntegrationConfig(max_correspondence_distance=2.0)
    with pytest.raises(ValueError, match="frame_rate"):
        integrate_dynamic(scans[:1], frame_rate=0.0)
    with pytest.raises(ValueError, match="voxel_size"):
        integrate_dynamic(scans[:1], voxel_size=-0.01)
    with pytest.raises(ValueError, match="min_distance"):
        integrate_dynamic(scans[:1], min_distance=np.nan)
    with pytest.raises(ValueError, match="robust_sigmas"):
        DynamicIntegrationConfig(robust_sigmas=-1.0)
    with pytest.raises(ValueError, match="frame_rate"):
        synthesize_times_from_azimuth(np.ones((3, 3)), -1.0)


# ---------------------------------------------------------------------------------------------
# Real data: the KITTI frames drive forward
# ---------------------------------------------------------------------------------------------


@pytest.mark.realdata
def test_kitti_frames_move_forward(real_data):
    folder = real_data / "kitti_raw_2011_09_26"
    scans = [
        np.fromfile(folder / f"{k:010d}" / "velodyne.bin", np.float32).reshape(-1, 4)
        for k in range(4)
    ]
    cloud = integrate_dynamic(scans)
    step = np.linalg.norm(np.diff(cloud.T_first_scanend[:, :3, 3], axis=0), axis=1)
    intra = np.linalg.norm(
        cloud.T_first_scanend[:, :3, 3] - cloud.T_first_scanbegin[:, :3, 3], axis=1
    )
    # the car drives at ~2.2 m/s (kiss-icp agrees, docs/BENCHMARKS.md); the motion within a
    # scan matches the motion between scans
    assert np.all((step > 0.15) & (step < 0.3)), step
    assert_allclose(intra, 0.22, atol=0.05)
    assert cloud.T_first_scanend[-1, 0, 3] > 0.6  # forward is +x
