"""Refining the intrinsics with the extrinsic (issue 47): where the truth is exact, frames at
several depths give back a focal length that was given wrong, and the pose with it; frames that
cannot tell them apart keep the given camera; a job that cannot refine is refused in one line."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from nbcalib.camera import example_camera, offset_intrinsics
from nbcalib.config import CalibrationConfig
from nbcalib.errors import InputError
from nbcalib.registration.pair import RegistrationPair
from nbcalib.registration.refine import refine
from nbcalib.teaching import textured_box
from nbcalib.transforms import invert_T, pose_error, se3_exp


def _pairs(true, given, rng, backs=(4.0, 7.0, 12.0)):
    out = []
    for k, back in enumerate(backs):
        image, points, intensities = textured_box(true, back, rng)
        out.append(RegistrationPair(given, image, points, intensities, f"room_{k}"))
    return out


def _config(**kw):
    return replace(CalibrationConfig().refine, pyramid_levels=0, **kw)


@pytest.mark.parametrize("model", ["pinhole", "fisheye"])
def test_a_focal_length_given_wrong_comes_back_with_the_pose(model, rng):
    true = example_camera(model, 320, 240)
    given = offset_intrinsics(true, focal_scale=1.02)
    pairs = _pairs(true, given, rng)
    start = se3_exp(np.array([0.02, -0.01, 0.03, 0.004, -0.003, 0.002]))
    result = refine(pairs, start, _config(intrinsics="focal"))
    found = result.intrinsics
    assert found.refined, found.summary()
    assert found.focal_scale == pytest.approx(1 / 1.02, abs=0.002), found.summary()
    assert result.camera.intrinsics[0] == pytest.approx(true.intrinsics[0], rel=0.002)
    dt, dr = pose_error(invert_T(result.T_camera_lidar), np.eye(4))
    dt0, _ = pose_error(invert_T(found.T_pose_only), np.eye(4))
    assert dt < 0.01 and dr < 0.1, (dt, dr)
    assert dt < dt0  # the pose found with the wrong focal length had absorbed it
    assert abs(found.correlation) < 1.0 and 0 < found.focal_bound_percent < 0.5
    record = found.to_record()
    assert record["refined"] and record["camera"]["intrinsics"][0] == result.camera.intrinsics[0]


def test_frames_at_one_depth_keep_the_given_camera(rng):
    true = example_camera("pinhole", 320, 240)
    given = offset_intrinsics(true, focal_scale=1.02)
    pairs = _pairs(true, given, rng, backs=(12.0, 12.0, 12.0))
    # a flat wall only: depth cannot tell focal length from forward motion
    far = [p.points_lidar[:, 2] >= 12.0 - 1e-9 for p in pairs]
    pairs = [
        replace(p, points_lidar=p.points_lidar[f], intensities=p.intensities[f])
        for p, f in zip(pairs, far)
    ]
    result = refine(pairs, np.eye(4), _config(intrinsics="focal"))
    assert not result.intrinsics.refined
    assert "focal length" in result.intrinsics.reason
    assert result.camera is given
    assert np.array_equal(result.T_camera_lidar, result.intrinsics.T_pose_only)


def test_a_job_that_cannot_refine_is_refused_before_any_work(rng):
    cam = example_camera("pinhole", 160, 120)
    image, points, intensities = textured_box(cam, 6.0, rng, n=2000)
    pair = RegistrationPair(cam, image, points, intensities, "one")
    with pytest.raises(InputError, match="at least 3 pairs"):
        refine([pair], np.eye(4), _config(intrinsics="focal"))
    equi = example_camera("equirectangular", 160, 80)
    pairs = [RegistrationPair(equi, np.zeros((80, 160), np.uint8), points, intensities)] * 3
    with pytest.raises(InputError, match="equirectangular"):
        refine(pairs, np.eye(4), _config(intrinsics="focal"))
    with pytest.raises(ValueError, match="nelder_mead"):
        _config(intrinsics="focal", optimizer="nelder_mead")
    with pytest.raises(ValueError, match="intrinsics must be"):
        _config(intrinsics="skew")


def test_the_report_check_flags_a_wrong_focal_length_and_passes_the_true_one(rng):
    from nbcalib.report.intrinsics import check_intrinsics

    true = example_camera("pinhole", 320, 240)
    config = _config()
    for given_scale, agrees in ((1.02, False), (1.0, True)):
        given = offset_intrinsics(true, focal_scale=given_scale)
        pairs = _pairs(true, given, rng)
        T = refine(pairs, np.eye(4), config).T_camera_lidar  # the pose absorbs what it can
        check = check_intrinsics(pairs, T, config, tolerance=0.003)
        assert check.checked and check.agrees is agrees, check.note
        assert check.focal_scale == pytest.approx(1 / given_scale, abs=0.004), check.note
        assert ("looks" in check.note) is not agrees
    one = check_intrinsics(pairs[:1], T, config, tolerance=0.003)
    assert not one.checked and one.agrees and "not checked" in one.note


def test_the_report_judges_the_pose_alone_with_the_result_camera(rng, monkeypatch):
    from nbcalib.report import quality
    from nbcalib.report.config import AssessConfig

    seen = []

    def restarts(pairs, T, config, acfg, step):  # the report's restarts: pose alone
        seen.append(config.intrinsics)
        return np.zeros((0, 6))

    monkeypatch.setattr(quality, "_restart_offsets", restarts)
    cam = example_camera("pinhole", 160, 120)
    box = textured_box(cam, 6.0, rng, n=4000)
    pairs = [RegistrationPair(cam, *box, f"same view {k}") for k in range(3)]  # one view
    acfg = AssessConfig(restarts=1, curve_samples=3)
    q = quality.assess(pairs, np.eye(4), config=_config(intrinsics="focal"), assess_config=acfg)
    assert seen == [None]
    assert q.intrinsics_check["checked"]
