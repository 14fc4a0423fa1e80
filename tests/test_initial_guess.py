"""The initial guess end to end on synthetic correspondences, for every camera model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.errors import InputError
from nbcalib.initial_guess import (
    estimate_initial_guess,
    synthetic_correspondences,
    translation_from_bearings,
)
from nbcalib.metrics import pose_errors
from nbcalib.synthetic import default_T_camera_lidar
from nbcalib.transforms import invert_T, make_T, so3_exp, transform_points

#: the paper's success criterion for an initial guess
MAX_ROTATION_DEG = 1.0
MAX_TRANSLATION_M = 0.5

R_OPTICAL_BODY = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def _camera_looking(yaw_deg: float, t_lidar_camera=(0.1, -0.15, 0.05)) -> np.ndarray:
    """T_camera_lidar of a camera at t looking along LiDAR yaw (0 forward, 180 backwards)."""
    R_lidar_camera = so3_exp(np.array([0.0, 0.0, math.radians(yaw_deg)])) @ R_OPTICAL_BODY.T
    return invert_T(make_T(R_lidar_camera, np.array(t_lidar_camera)))


def _assert_success(guess, truth):
    err = pose_errors(guess.T_camera_lidar, truth)
    assert err["rotation_error_deg"] < MAX_ROTATION_DEG, err
    assert err["translation_error_m"] < MAX_TRANSLATION_M, err
    assert guess.success


@pytest.mark.parametrize("model", CAMERA_MODELS)
def test_every_camera_model_with_80_percent_outliers(model):
    camera = example_camera(model, 640, 480)
    truth = default_T_camera_lidar("spinning", 7)
    c = synthetic_correspondences(camera, truth, 3, n_inliers=60, outlier_fraction=0.8)
    # RANSAC's robustness alone: 60 matches with 1.4 px of noise bound a wide 640 x 480 camera's
    # pose to ~0.15 deg, which the precision test's factor for learned matches' shared error
    # (tested below) would refuse
    guess = estimate_initial_guess(
        camera, c.uv_camera, c.points_lidar, ransac_iterations=4096, precision_scale=0.0
    )
    _assert_success(guess, truth)
    # the inliers found are true correspondences, and most true ones are found
    assert np.mean(c.is_inlier[guess.inliers]) > 0.95
    assert np.mean(guess.inliers[c.is_inlier]) > 0.8
    assert guess.rms_px < 3.0


@pytest.mark.parametrize(
    ("model", "yaw"), [("fisheye", 90.0), ("omnidir", -120.0), ("equirectangular", 180.0)]
)
def test_wide_cameras_looking_sideways_or_backwards(model, yaw):
    camera = example_camera(model, 640, 480)
    truth = _camera_looking(yaw)
    c = synthetic_correspondences(camera, truth, 5, n_inliers=50, outlier_fraction=0.85)
    guess = estimate_initial_guess(
        camera, c.uv_camera, c.points_lidar, ransac_iterations=4096, precision_scale=0.0
    )
    _assert_success(guess, truth)


def test_same_seed_same_answer_and_reference_procedure():
    camera = example_camera("plumb_bob", 640, 480)
    truth = default_T_camera_lidar("spinning", 2)
    c = synthetic_correspondences(camera, truth, 1, n_inliers=80, outlier_fraction=0.7)
    a = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, seed=4)
    b = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, seed=4, parallel=False)
    assert np.array_equal(a.T_camera_lidar, b.T_camera_lidar)
    ref = estimate_initial_guess(
        camera,
        c.uv_camera,
        c.points_lidar,
        seed=4,
        candidates=1,
        local_optimization=False,
        initial_translation="zero",
    )
    assert np.array_equal(ref.T_camera_lidar_start[:3, 3], np.zeros(3))
    assert ref.candidate == 0
    _assert_success(ref, truth)


def test_the_same_inputs_asked_again_give_the_kept_estimate(monkeypatch):
    """Matching's test and the initial-guess stage estimate from the same correspondences:
    the second is the first's result; any other input (a value, the weights, a setting, the
    seed) is estimated anew."""
    import nbcalib.initial_guess.estimate as estimate

    camera = example_camera("plumb_bob", 640, 480)
    truth = default_T_camera_lidar("spinning", 2)
    c = synthetic_correspondences(camera, truth, 1, n_inliers=60, outlier_fraction=0.5)
    runs = []
    real = estimate._estimate
    monkeypatch.setattr(estimate, "_estimate", lambda *a: runs.append(1) or real(*a))
    monkeypatch.setattr(estimate, "_MEMO", {})
    uv = c.uv_camera.copy()
    first = estimate_initial_guess(camera, uv, c.points_lidar, seed=1)
    assert estimate_initial_guess(camera, uv.copy(), c.points_lidar, seed=1) is first
    assert len(runs) == 1
    weights = np.ones(len(uv))
    others = [
        dict(seed=2),
        dict(seed=1, weights=weights),
        dict(seed=1, ransac_iterations=1000),
    ]
    for kwargs in others:
        assert estimate_initial_guess(camera, uv, c.points_lidar, **kwargs) is not first
    uv[0, 0] += 1.0  # an array changed in place is another input
    estimate_initial_guess(camera, uv, c.points_lidar, seed=1)
    assert len(runs) == 1 + len(others) + 1
    assert len(estimate._MEMO) == estimate._MEMO_SIZE  # the oldest went


def test_confidence_weights_favour_confident_matches():
    camera = example_camera("pinhole", 640, 480)
    truth = _camera_looking(-40.0)
    c = synthetic_correspondences(camera, truth, 8, n_inliers=60, outlier_fraction=0.6)
    uv = c.uv_camera.copy()
    # a coherent bias: 30 of the outliers are a shifted copy of true correspondences
    fakes = np.flatnonzero(~c.is_inlier)[:30]
    donors = np.flatnonzero(c.is_inlier)[:30]
    uv[fakes] = uv[donors] + [6.0, 0.0]
    points = c.points_lidar.copy()
    points[fakes] = points[donors]
    confidence = np.where(c.is_inlier, 0.9, 0.05)
    # the weights act in Eq. 1 over all correspondences; the polish refit of the inliers would
    # drop the 6-pixel copies either way, so it is off here
    weighted = estimate_initial_guess(camera, uv, points, weights=confidence, polish=False)
    plain = estimate_initial_guess(camera, uv, points, polish=False)
    _assert_success(weighted, truth)
    # the biased copies pull the unweighted pose half-way (a few pixels); weighted, they hardly do
    err_w = pose_errors(weighted.T_camera_lidar, truth)["rotation_error_deg"]
    err_p = pose_errors(plain.T_camera_lidar, truth)["rotation_error_deg"]
    assert err_w < 0.5 * err_p
    assert np.mean(weighted.errors[donors]) < 0.7 * np.mean(plain.errors[donors])
    with pytest.raises(ValueError, match="weights"):
        estimate_initial_guess(camera, uv, points, weights=np.ones(3))


def test_pure_outliers_are_flagged_as_failure(rng):
    camera = example_camera("pinhole", 640, 480)
    uv = rng.uniform([0, 0], [639, 479], (300, 2))
    points = rng.normal(size=(300, 3)) * 10.0
    guess = estimate_initial_guess(camera, uv, points, ransac_iterations=2000)
    assert not guess.success and guess.n_inliers < guess.min_inliers
    assert "FAILED" in guess.summary()


def test_wrong_matches_that_pass_the_inlier_count_are_not_distinct():
    # real KITTI frames: ~10 % chance inliers among wrong matches passed a count-only flag
    rng = np.random.default_rng(0)
    camera = example_camera("pinhole", 640, 480)
    uv = rng.uniform([0, 0], [639, 479], (150, 2))
    points = rng.uniform([-20, -10, 2], [20, 10, 40], (150, 3))
    guess = estimate_initial_guess(camera, uv, points, ransac_iterations=2000, min_inliers=3)
    assert guess.n_inliers >= 3, "the count test alone would pass"
    assert guess.distinctiveness < 2.0
    assert not guess.success and "not distinct" in guess.failure
    # the same correspondences with a real answer among them are distinct
    truth = default_T_camera_lidar("spinning", 7)
    c = synthetic_correspondences(camera, truth, 3, n_inliers=60, outlier_fraction=0.8)
    good = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, ransac_iterations=2000)
    assert good.success and good.failure == "" and good.distinctiveness > 3.0


def test_a_pose_that_only_re_explains_the_answers_inliers_is_no_rival():
    """Half the correct matches sit near the principal point, which a roll about the optical
    axis hardly moves: poses rolled 5+ degrees explain them too. Counted over all
    correspondences that made the good guess "not distinct"; only the answer's outliers may
    support a rival, and they support none."""
    rng = np.random.default_rng(3)
    camera = example_camera("pinhole", 640, 480)
    truth = default_T_camera_lidar("spinning", 2)
    centre = rng.uniform([-30, -30], [30, 30], (250, 2)) + np.array([319.5, 239.5])
    spread = rng.uniform([0, 0], [639, 479], (150, 2))
    uv = np.vstack([centre, spread])
    depth = rng.uniform(5, 40, len(uv))
    points = transform_points(invert_T(truth), camera.unproject(uv) * depth[:, None])
    uv_noisy = uv + rng.normal(scale=0.5, size=uv.shape)
    wrong_uv = rng.uniform([0, 0], [639, 479], (200, 2))
    wrong_points = rng.uniform([-20, -10, 2], [20, 10, 40], (200, 3))
    guess = estimate_initial_guess(
        camera, np.vstack([uv_noisy, wrong_uv]), np.vstack([points, wrong_points]), seed=1
    )
    _assert_success(guess, truth)
    assert guess.runner_up < guess.support / 4


def test_a_rival_that_explains_nearly_as_much_in_all_fails_the_guess():
    """Both counts must leave the answer ahead: its own evidence 2x, all evidence 1.5x."""
    from dataclasses import replace

    camera = example_camera("pinhole", 640, 480)
    truth = default_T_camera_lidar("spinning", 7)
    c = synthetic_correspondences(camera, truth, 3, n_inliers=60, outlier_fraction=0.8)
    good = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, ransac_iterations=2000)
    assert good.success and good.min_shared_distinctiveness == 1.5
    assert good.support >= 1.5 * max(good.runner_up_shared, 1)
    # a real-frame case: 27 inliers, a rival with 12 of the rest but 21 in all (153 deg off)
    close = replace(good, support=27, runner_up=12, runner_up_shared=21)
    assert close.failure.startswith("not distinct") and "21 correspondences" in close.failure
    assert replace(close, runner_up_shared=18).failure == ""


def test_points_behind_the_camera_count_as_outliers():
    camera = example_camera("plumb_bob", 640, 480)
    truth = _camera_looking(0.0)
    c = synthetic_correspondences(camera, truth, 2, n_inliers=60, outlier_fraction=0.5)
    # mirror some outliers' points through the LiDAR: they are behind the camera
    points = c.points_lidar.copy()
    mirrored = np.flatnonzero(~c.is_inlier)[:20]
    points[mirrored] = -points[mirrored]
    guess = estimate_initial_guess(camera, c.uv_camera, points)
    _assert_success(guess, truth)
    p_camera = transform_points(guess.T_camera_lidar, points)
    assert not guess.inliers[p_camera[:, 2] <= 0].any()
    assert np.all(np.isinf(guess.errors[p_camera[:, 2] <= 0]))


def test_translation_from_bearings_is_exact_for_exact_rays(rng):
    camera = example_camera("pinhole", 640, 480)
    truth = _camera_looking(30.0)
    c = synthetic_correspondences(
        camera, truth, rng, n_inliers=20, outlier_fraction=0.0, noise_px=0.0, range_m=(1.0, 5.0)
    )
    t = translation_from_bearings(truth[:3, :3], camera.unproject(c.uv_camera), c.points_lidar)
    np.testing.assert_allclose(t, truth[:3, 3], atol=1e-9)
    far = translation_from_bearings(
        truth[:3, :3], camera.unproject(c.uv_camera), c.points_lidar, max_norm=0.01
    )
    assert np.array_equal(far, np.zeros(3))


def test_too_few_correspondences():
    camera = example_camera("pinhole", 64, 48)
    with pytest.raises(InputError, match="too few correspondences"):
        estimate_initial_guess(camera, [[1.0, 2.0], [3.0, 4.0]], [[5.0, 0, 0], [6.0, 1, 0]])
    with pytest.raises(ValueError, match="initial_translation"):
        estimate_initial_guess(
            camera, np.zeros((3, 2)), np.ones((3, 3)), initial_translation="guess"
        )


def _far_street(seed, outlier_fraction=0.8):
    """A camera that sees only far points (8-50 m): the translation along its axis is weak."""
    camera = example_camera("plumb_bob", 1280, 960)
    truth = _camera_looking(20.0)
    c = synthetic_correspondences(
        camera, truth, seed, n_inliers=80, outlier_fraction=outlier_fraction, range_m=(8.0, 50.0)
    )
    return camera, truth, c


def _pushed_along_axis(T, metres, degrees=0.0):
    """``T_camera_lidar`` with the camera moved ``metres`` along its optical axis, turned."""
    out = so3_exp(np.array([0.0, math.radians(degrees), 0.0])) @ T[:3, :3]
    return make_T(out, T[:3, 3] + np.array([0.0, 0.0, -metres]))


def test_translation_ransac_recovers_the_translation_for_a_known_rotation():
    from nbcalib.initial_guess import translation_ransac

    camera, truth, c = _far_street(3)
    bearings = camera.unproject(c.uv_camera)
    start = _pushed_along_axis(truth, 1.3)[:3, 3]
    t, n = translation_ransac(
        camera, truth[:3, :3], c.uv_camera, c.points_lidar, bearings, t_start=start, seed=1
    )
    assert np.linalg.norm(t - truth[:3, 3]) < 0.1
    assert n >= 0.8 * np.count_nonzero(c.is_inlier)
    again = translation_ransac(
        camera, truth[:3, :3], c.uv_camera, c.points_lidar, bearings, t_start=start, seed=1
    )
    assert np.array_equal(again[0], t)
    # no hypothesis drawn: the start stays
    kept, _ = translation_ransac(
        camera, truth[:3, :3], c.uv_camera, c.points_lidar, bearings, t_start=start, iterations=0
    )
    assert np.array_equal(kept, start)


def test_translation_ransac_equals_its_one_at_a_time_reference():
    from nbcalib.initial_guess import translation_ransac
    from nbcalib.reference.ransac import translation_ransac as reference

    camera, truth, c = _far_street(4)
    bearings = camera.unproject(c.uv_camera)
    for seed, start in ((0, None), (3, _pushed_along_axis(truth, 0.8)[:3, 3])):
        R = _pushed_along_axis(truth, 0.0, 0.3)[:3, :3]  # a slightly wrong rotation: ties differ
        args = (camera, R, c.uv_camera, c.points_lidar, bearings)
        fast = translation_ransac(*args, seed=seed, t_start=start, iterations=300)
        slow = reference(*args, seed=seed, t_start=start, iterations=300)
        assert fast[1] == slow[1]
        np.testing.assert_allclose(fast[0], slow[0], atol=1e-9)


def test_polish_undoes_a_pull_along_the_weak_direction():
    """LM over all correspondences can end metres off along a weakly constrained direction
    (docs/BENCHMARKS.md: 1.3 m on a street pair); from such a pose the polish step gets back
    to the truth, where the unpolished pose stays off."""
    from nbcalib.initial_guess.estimate import _polish

    camera, truth, c = _far_street(5)
    pulled = _pushed_along_axis(truth, 1.3, degrees=0.3)
    start = pose_errors(pulled, truth)
    assert start["translation_error_m"] > 1.0
    T = _polish(
        camera,
        c.uv_camera,
        c.points_lidar,
        camera.unproject(c.uv_camera),
        pulled,
        np.ones(len(c.uv_camera)),
        threshold=5.0,
        width=2.0,
        seed=0,
        iterations=1000,
    )
    err = pose_errors(T, truth)
    assert err["translation_error_m"] < 0.2 and err["rotation_error_deg"] < 0.2, err


def test_polish_does_not_hurt_a_good_guess():
    camera, truth, c = _far_street(7, outlier_fraction=0.7)
    polished = estimate_initial_guess(camera, c.uv_camera, c.points_lidar)
    plain = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, polish=False)
    _assert_success(polished, truth)
    assert polished.n_inliers >= plain.n_inliers - 2


def test_good_guesses_in_a_room_are_distinct():
    """Points 1-10 m away, the camera up to 30 cm from the LiDAR: near points' parallax gives
    rotations several degrees off the answer rotation-only support, which made a rotation-only
    distinctiveness test fail 28 % of good room guesses (docs/BENCHMARKS.md). Counted with full
    poses, the right answer is distinct."""
    camera = example_camera("pinhole")
    for trial in range(8):
        truth = default_T_camera_lidar("spinning", trial)
        c = synthetic_correspondences(
            camera, truth, [trial, 50], n_inliers=50, outlier_fraction=0.5, range_m=(1.0, 10.0)
        )
        guess = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, seed=trial)
        _assert_success(guess, truth)
        assert guess.support == guess.n_inliers and guess.distinctiveness >= 2.0


def test_pose_uncertainty_covers_the_error_of_noisy_correct_matches():
    # correct matches with 1 px noise: the least-squares bound holds the guess's error about as
    # often as its confidence says (here 95 %, over 60 draws), and more matches shrink it
    from nbcalib.initial_guess import pose_uncertainty

    camera = example_camera("pinhole", 640, 480)
    truth = default_T_camera_lidar("spinning", 7)
    held_t = held_r = 0
    bounds = {}
    for seed in range(60):
        n = 20 if seed % 2 else 80
        c = synthetic_correspondences(camera, truth, seed, n_inliers=n, outlier_fraction=0.0)
        guess = estimate_initial_guess(camera, c.uv_camera, c.points_lidar, seed=seed)
        inl = guess.inliers
        t_b, r_b = pose_uncertainty(
            camera, guess.T_camera_lidar, c.uv_camera[inl], c.points_lidar[inl]
        )
        err = pose_errors(guess.T_camera_lidar, truth)
        held_t += err["translation_error_m"] <= t_b
        held_r += err["rotation_error_deg"] <= r_b
        bounds.setdefault(n, []).append(r_b)
    assert 0.85 <= held_t / 60 <= 1.0 and 0.85 <= held_r / 60 <= 1.0, (held_t, held_r)
    assert np.median(bounds[80]) < 0.7 * np.median(bounds[20])
    few = synthetic_correspondences(camera, truth, 0, n_inliers=3, outlier_fraction=0.0)
    assert pose_uncertainty(camera, truth, few.uv_camera, few.points_lidar) == (math.inf,) * 2


def test_a_guess_its_matches_bound_too_loosely_is_refused():
    # matches that share an error (a rendered LiDAR image against a photograph) fit a wrong pose
    # as well as noise allows: the success test asks that precision_scale times the bounds their
    # noise leaves be within the paper's 1 deg / 0.5 m. Few noisy matches on one side of the
    # image, all shifted alike, put the pose over a degree off: refused, and so without the test
    camera = example_camera("pinhole", 640, 480)
    truth = default_T_camera_lidar("spinning", 7)
    c = synthetic_correspondences(camera, truth, 2, n_inliers=40, outlier_fraction=0.3)
    rng = np.random.default_rng(2)
    uv = c.uv_camera + rng.normal(0.0, 3.0, c.uv_camera.shape)
    uv[c.is_inlier] += [14.0, -6.0]  # the shared error: about 1.2 deg
    loose = estimate_initial_guess(camera, uv, c.points_lidar)
    assert pose_errors(loose.T_camera_lidar, truth)["rotation_error_deg"] > 1.0
    assert not loose.success and loose.failure.startswith("imprecise"), loose.failure
    assert estimate_initial_guess(camera, uv, c.points_lidar, precision_scale=0.0).success
    # many precise matches pass
    many = synthetic_correspondences(camera, truth, 2, n_inliers=600, outlier_fraction=0.3)
    tight = estimate_initial_guess(camera, many.uv_camera, many.points_lidar)
    assert tight.success and tight.precise and 0 < tight.bound_deg < 0.05, tight.summary()
