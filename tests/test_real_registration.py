"""Fine registration on real data (issue 5 item 6): five KITTI single-scan pairs from a start
1 degree / 5 cm off the reference calibration end closer to it.

Figures in benchmarks/bench_real_registration.py (docs/BENCHMARKS.md): from 1 degree / 5 cm,
KITTI 5-pair sets reach < 3 cm / 0.3 degree in only 0-20 % of random starts (the real-data NID
is flat and its minimum is off the reference). This start (seed 0 of the benchmark) converges
on frames 0-4 to 2.1 cm / 0.12 degree with 0, 1 and 2 pyramid levels alike, so the test guards
that a case that works keeps working; the bounds are ~2-3 x the measurement and well inside the
start, so doing nothing fails.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from tolerances import TOL

from nbcalib.io.camera_file import load_camera
from nbcalib.io.ground_truth import read_ground_truth
from nbcalib.metrics import pose_errors
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.inputs import gather_files
from nbcalib.preprocess.prepare import prepare_pair
from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine
from nbcalib.transforms import invert_T, make_T, so3_exp


def _perturbed(T_camera_lidar, seed, *, angle_deg=1.0, distance=0.05):
    """Turn ``T_lidar_camera`` by ``angle_deg`` and move the camera centre by ``distance``."""
    rng = np.random.default_rng(seed)
    axis, direction = rng.standard_normal(3), rng.standard_normal(3)
    axis /= np.linalg.norm(axis)
    direction /= np.linalg.norm(direction)
    T_lidar_camera = invert_T(T_camera_lidar)
    R = so3_exp(math.radians(angle_deg) * axis) @ T_lidar_camera[:3, :3]
    return invert_T(make_T(R, T_lidar_camera[:3, 3] + distance * direction))


@pytest.mark.slow
@pytest.mark.realdata
def test_kitti_five_pairs_converge_towards_reference(real_data):
    kitti = real_data / "kitti_raw_2011_09_26"
    calib = kitti / "calib" / "calib_normalized_cam2rect.json"
    camera, T_ref = load_camera(calib), read_ground_truth(calib)
    # the pairs as `nbcalib preprocess` makes (and writes) them for five single scans
    config = PreprocessConfig(mode="static")
    inputs = [
        gather_files(
            [kitti / f"{k:010d}" / "velodyne.bin"],
            kitti / f"{k:010d}" / "image_02.png",
            config,
            name=f"{k:010d}",
        )
        for k in range(5)
    ]
    pairs = []
    for pair in inputs:
        p = prepare_pair(pair, config)
        pairs.append(RegistrationPair(camera, p.image, p.points_lidar, p.intensities, p.name))
    assert len(pairs) == 5

    T_init = _perturbed(T_ref, seed=0)
    start = pose_errors(T_init, T_ref)
    assert start["rotation_error_deg"] == pytest.approx(1.0)
    assert start["translation_error_m"] == pytest.approx(0.05)

    # accuracy, not threading, is under test (the serial and parallel kernels agree bit for bit):
    # on a loaded machine the parallel kernel's threads cost far more than they save
    result = refine(pairs, T_init, replace(RefineConfig(), parallel=False))
    end = pose_errors(result.T_camera_lidar, T_ref)
    assert end["rotation_error_deg"] < TOL["real_kitti_5pairs_rotation_deg"]["atol"], end
    assert end["translation_error_m"] < TOL["real_kitti_5pairs_translation_m"]["atol"], end
    assert all(min(h.visible_points) > 10_000 for h in result.history)
