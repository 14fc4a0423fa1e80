"""`nbcalib calibrate` on a small work directory with a known answer."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.config import CalibrationConfig
from nbcalib.errors import FAILED_STATUS
from nbcalib.io.calib_json import read_calib_json
from nbcalib.preprocess.lidar_image import (
    estimate_lidar_fov,
    make_virtual_camera,
    render_lidar_image,
)
from nbcalib.products import PairData
from nbcalib.registration.refine import (
    RefineConfig,
    RegistrationPair,
    build_cost,
    downscale_camera,
    downscale_image,
    refine,
    visible_subset,
)
from nbcalib.registration.trust import TrustRegion
from nbcalib.transforms import invert_T, pose_error, pose_from_xyz_quat, pose_to_xyz_quat, se3_exp
from nbcalib.workdir import WorkDir, make_calib
from tests.test_nid import textured_scene
from tests.tolerances import TOL


@pytest.fixture
def workdir(tmp_path):
    """One pair whose LiDAR intensities are a function of the image at the true projection
    (identity extrinsic): the NID minimum is at the truth."""
    rng = np.random.default_rng(7)
    cam = example_camera("plumb_bob", 400, 300)
    image, points, intensities = textured_scene(cam, rng, n=40000, blur=2.5)
    vcam, T_vcam_lidar = make_virtual_camera(estimate_lidar_fov(points))
    lidar_image = render_lidar_image(vcam, T_vcam_lidar, points, intensities)
    work = WorkDir(tmp_path / "work")
    work.prepare()
    work.write_pair(
        PairData("000000", np.round(image * 255).astype(np.uint8), points, intensities, lidar_image)
    )
    work.write_calib(make_calib(cam, ["000000"]))
    return work


def test_calibrate_recovers_the_truth_from_init(workdir, capsys):
    T_start = se3_exp(np.array([0.04, -0.03, 0.02, 0.012, -0.008, 0.01]))  # ~5 cm, ~1 degree
    init = ",".join(f"{v:.9f}" for v in pose_to_xyz_quat(invert_T(T_start)))
    assert main(["calibrate", str(workdir.path), f"--init={init}"]) == 0
    calib = read_calib_json(workdir.calib_path)
    T = calib.get_T_camera_lidar("T_lidar_camera")
    dt, dr = pose_error(invert_T(T), np.eye(4))
    assert dt < 0.005 and dr < 0.05, (dt, dr)
    fig = calib.to_dict()["nbcalib"]["calibration"]
    assert fig["nid"] < fig["nid_start"] and fig["start"] == "--init"
    json.dumps(fig)
    start = pose_from_xyz_quat(fig["start_T_lidar_camera"])
    np.testing.assert_allclose(start, invert_T(T_start), atol=1e-8)  # the report's "before"
    err = capsys.readouterr().err
    # a 400 x 300 image: no pyramid level would keep min_pyramid_size (240) pixels
    assert "outer 1 (level 0): NID" in err and "level 1" not in err


def test_a_run_held_by_the_trust_region_fails_and_writes_no_result(workdir, capsys):
    """5 cm off, a 2 cm / 0.5 deg region: the run ends on its edge, exit 3, no result left."""
    calib = read_calib_json(workdir.calib_path)
    calib.set_T_camera_lidar("T_lidar_camera", np.eye(4))  # an earlier result, now stale
    workdir.write_calib(calib)
    T_start = se3_exp(np.array([0.04, -0.03, 0.02, 0.012, -0.008, 0.01]))
    init = ",".join(f"{v:.9f}" for v in pose_to_xyz_quat(invert_T(T_start)))
    args = ["--trust-translation", "0.02", "--trust-rotation", "0.5", "--force"]
    args += ["--init-uncertainty", "0.005", "0.1"]
    assert main(["calibrate", str(workdir.path), f"--init={init}", *args]) == FAILED_STATUS
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("nbcalib calibrate: failed: fine registration ran to the edge of its")
    assert "the region is 2 cm / 0.5 deg" in err and "--init" in err
    calib = read_calib_json(workdir.calib_path)
    assert not calib.has_result("T_lidar_camera")  # the old result went too: nothing stale
    fig = calib.to_dict()["nbcalib"]["calibration"]
    assert fig["trust_region"] == {"translation_m": 0.02, "rotation_deg": 0.5}
    assert fig["at_trust_boundary"] is True and fig["failed"] in err
    assert fig["start_uncertainty"] == {"translation_m": 0.005, "rotation_deg": 0.1}
    moved = fig["change_from_start"]
    assert moved["translation_m"] <= 0.02 + 1e-9 and moved["rotation_deg"] <= 0.5 + 1e-9
    assert len(fig["attempted_T_lidar_camera"]) == 7
    # nothing to evaluate or report: a user error each, naming the file
    assert main(["evaluate", str(workdir.path), "--ground-truth", str(workdir.calib_path)]) == 2
    assert main(["report", str(workdir.path)]) == 2
    assert "calib.json" in capsys.readouterr().err


def test_the_api_raises_when_the_run_ends_on_the_trust_region(workdir):
    from nbcalib.errors import RegistrationFailed
    from nbcalib.pipeline import Calibrator
    from nbcalib.products import Start

    config = CalibrationConfig(refine=RefineConfig(trust_translation=0.02, trust_rotation_deg=0.5))
    T_start = se3_exp(np.array([0.04, -0.03, 0.02, 0.012, -0.008, 0.01]))
    start = Start.from_values(pose_to_xyz_quat(invert_T(T_start)), "--init")
    with pytest.raises(RegistrationFailed, match="edge of its trust region") as info:
        Calibrator(config, workdir=workdir.path).run(init=start, only="calibrate")
    assert info.value.result.at_trust_boundary


def test_calibrate_starts_from_the_initial_guess_in_calib_json(workdir):
    calib = read_calib_json(workdir.calib_path)
    calib.set_T_camera_lidar(
        "init_T_lidar_camera_auto", se3_exp(np.array([0.02, 0, 0, 0, 0.005, 0]))
    )
    workdir.write_calib(calib)
    assert main(["calibrate", str(workdir.path), "--max-outer", "3"]) == 0
    calib = read_calib_json(workdir.calib_path)
    assert calib.to_dict()["nbcalib"]["calibration"]["start"] == "init_T_lidar_camera_auto"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--init", "1,2,3"], "7 numbers"),
        (["--init", "a,b,c,d,e,f,g"], "7 numbers"),
        ([], "no initial guess"),
        (["--pairs", "0", "--init", "0,0,0,0,0,0,1"], "--pairs"),
        (["--init-uncertainty", "0.05", "1"], "--init-uncertainty needs --init"),
        (["--init", "0,0,0,0,0,0,1", "--init-uncertainty", "x", "1"], "two numbers"),
        (["--init", "0,0,0,0,0,0,1", "--trust-rotation", "-1"], "trust_rotation_deg"),
    ],
)
def test_calibrate_user_errors(workdir, capsys, args, message):
    assert main(["calibrate", str(workdir.path), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_calibrate_without_preprocessing(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path)]) == 2
    assert "run 'nbcalib preprocess' first" in capsys.readouterr().err


# --- coarse-to-fine pyramid of fine registration ----------------------------------------------


@pytest.mark.parametrize("model", ["plumb_bob", "fisheye", "omnidir", "equirectangular"])
@pytest.mark.parametrize("level", [1, 2])
def test_downscaled_camera_maps_pixels_like_block_averaging(model, level, rng):
    """Coarse pixel i averages fine pixels 2i, 2i+1: u_coarse = (u_fine + 0.5) / 2^k - 0.5."""
    cam = example_camera(model, 320, 240 if model != "equirectangular" else 160)
    coarse = downscale_camera(cam, level)
    f = 2**level
    assert (coarse.width, coarse.height) == (cam.width // f, cam.height // f)
    uv = np.column_stack([rng.uniform(5, cam.width - 5, 200), rng.uniform(5, cam.height - 5, 200)])
    bearings = cam.unproject(uv)
    ok = np.isfinite(bearings[:, 0])
    uv_coarse, valid = coarse.project(bearings[ok] * 3.0)
    assert valid.all()
    np.testing.assert_allclose(uv_coarse, (uv[ok] + 0.5) / f - 0.5, **TOL["camera_roundtrip_px"])


def test_downscaled_image_is_block_mean_then_equalised(rng):
    image = rng.random((61, 83))  # odd sizes: the last row / column is dropped
    coarse = downscale_image(image, 1)
    assert coarse.shape == (30, 41) and coarse.dtype == np.uint8
    blocks = image[:60, :82].reshape(30, 2, 41, 2).mean(axis=(1, 3))
    # equalisation is monotonic: the coarse image orders pixels as the block means do
    order = np.argsort(blocks.ravel(), kind="stable")
    assert np.all(np.diff(coarse.ravel()[order].astype(int)) >= 0)
    assert coarse.min() == 0 and coarse.max() == 255
    assert downscale_image(image, 0) is image


def test_refine_config_rejects_bad_pyramid():
    with pytest.raises(ValueError, match="pyramid_levels"):
        RefineConfig(pyramid_levels=-1)


def _small_textured_pair(rng) -> RegistrationPair:
    cam = example_camera("plumb_bob", 160, 120)
    image, points, intensities = textured_scene(cam, rng, n=4000, blur=1.5)
    return RegistrationPair(cam, image, points, intensities)


def _first_outer_evaluations(pair, **settings) -> int:
    """Evaluations of one outer iteration at full resolution from a fixed start."""
    T_start = se3_exp(np.array([0.01, -0.01, 0.0, 0.004, 0.0, -0.003]))
    config = RefineConfig(
        pyramid_levels=0, hidden_point_removal=False, parallel=False, max_outer=1, **settings
    )
    return refine([pair], T_start, config).history[0].evaluations


def test_lbfgs_ftol_reaches_the_optimiser(rng):
    """A tighter relative-reduction stop lets L-BFGS run longer; a bad one is refused."""
    pair = _small_textured_pair(rng)
    evaluations = {
        ftol: _first_outer_evaluations(pair, optimizer="lbfgs", lbfgs_ftol=ftol)
        for ftol in (1e-3, 1e-12)
    }
    assert evaluations[1e-12] > evaluations[1e-3], evaluations
    with pytest.raises(ValueError, match="lbfgs_ftol"):
        RefineConfig(lbfgs_ftol=0.0)


def test_nelder_mead_tolerances_reach_the_optimiser(rng):
    """SciPy's own stops (1e-6, 1e-8) make Nelder-Mead shrink its simplex far longer than the
    default's; a bad one is refused."""
    pair = _small_textured_pair(rng)
    evaluations = {
        fatol: _first_outer_evaluations(
            pair, optimizer="nelder_mead", nelder_mead_xatol=xatol, nelder_mead_fatol=fatol
        )
        for xatol, fatol in ((1e-6, 1e-8), (1e-4, 1e-5))
    }
    assert evaluations[1e-8] > evaluations[1e-5], evaluations
    with pytest.raises(ValueError, match="nelder_mead_xatol"):
        RefineConfig(nelder_mead_fatol=0.0)


def test_pyramid_widens_the_basin(rng):
    """From 3 degrees / 10 cm off, the coarse-to-fine run gets back to the truth; the single
    full-resolution level (the reference's procedure) does not move on this finely textured scene
    (measured: 10 cm / 3.05 degrees off at the end)."""
    cam = example_camera("plumb_bob", 320, 240)
    image, points, intensities = textured_scene(cam, rng, n=30000, blur=0.8)
    pair = RegistrationPair(cam, image, points, intensities)
    axis = np.array([0.6, -0.8, 0.0])
    T_start = se3_exp(np.concatenate([[0.06, 0.08, 0.0], axis * np.radians(3.0)]))
    ends = {}
    for levels in (0, 3):
        config = RefineConfig(
            optimizer="lbfgs",
            pyramid_levels=levels,
            min_pyramid_size=16,
            hidden_point_removal=False,
            parallel=False,
        )
        result = refine([pair], T_start, config)
        ends[levels] = pose_error(invert_T(result.T_camera_lidar), np.eye(4))
        assert result.history[0].level == levels
    assert ends[3][0] < 0.005 and ends[3][1] < 0.05, ends
    assert ends[0][0] > 0.02 or ends[0][1] > 0.2, ends


def test_hybrid_runs_nelder_mead_then_lbfgs_at_full_resolution(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, points, intensities = textured_scene(cam, rng, n=20000, blur=0.8)
    pair = RegistrationPair(cam, image, points, intensities)
    T_start = se3_exp(np.array([0.03, -0.02, 0.01, 0.012, -0.015, 0.006]))  # 3.6 cm, 1.3 deg
    config = RefineConfig(
        optimizer="hybrid", min_pyramid_size=16, hidden_point_removal=False, parallel=False
    )
    result = refine([pair], T_start, config)
    stages = [h.optimizer for h in result.history]
    first_lbfgs = stages.index("lbfgs")
    assert set(stages[:first_lbfgs]) == {"nelder_mead"} and set(stages[first_lbfgs:]) == {"lbfgs"}
    assert result.history[0].level == 2
    assert all(h.level == 0 for h in result.history[first_lbfgs:])
    assert result.converged
    # each outer iteration keeps the pose it ended at; moves between them are what it reports
    np.testing.assert_array_equal(result.history[-1].T_camera_lidar, result.T_camera_lidar)
    for before, step in zip([T_start] + [h.T_camera_lidar for h in result.history], result.history):
        moved_m, moved_deg = pose_error(invert_T(step.T_camera_lidar), invert_T(before))
        assert moved_m == pytest.approx(step.translation_change, abs=1e-12)
        assert moved_deg == pytest.approx(step.rotation_change_deg, abs=1e-9)
    dt, dr = pose_error(invert_T(result.T_camera_lidar), np.eye(4))
    assert dt < 0.005 and dr < 0.05, (dt, dr)
    # well inside the default trust region (0.5 m / 5 deg): not on its edge
    assert not result.at_trust_boundary
    assert abs(result.moved_translation - 0.037) < 0.006 and result.moved_rotation_deg < 1.4
    with pytest.raises(ValueError, match="optimizer"):
        RefineConfig(optimizer="bfgs")


def test_pyramid_levels_keep_a_minimum_image_size():
    from nbcalib.registration.refine import _usable_levels

    def pair(w, h):
        return RegistrationPair(
            example_camera("pinhole", w, h), np.zeros((h, w)), np.zeros((1, 3)), [0.0]
        )

    config = RefineConfig(pyramid_levels=2)  # min_pyramid_size 240
    assert _usable_levels([pair(1920, 1080)], config) == 2
    assert _usable_levels([pair(640, 480)], config) == 1
    assert _usable_levels([pair(400, 300)], config) == 0
    assert _usable_levels([pair(1920, 1080), pair(640, 480)], config) == 1  # the smallest rules
    assert (
        _usable_levels([pair(400, 300)], RefineConfig(pyramid_levels=3, min_pyramid_size=16)) == 3
    )


@pytest.mark.parametrize("optimizer", ["lbfgs", "nelder_mead", "hybrid"])
def test_refine_stays_in_the_trust_region_when_the_minimum_lies_outside(rng, optimizer):
    """The truth is 8 cm from the start, the region 3 cm / 1 deg: the run ends on its edge."""
    cam = example_camera("plumb_bob", 320, 240)
    image, points, intensities = textured_scene(cam, rng, n=20000, blur=0.8)
    T_start = se3_exp(np.array([0.08, 0.0, 0.0, 0.0, 0.0, 0.0]))  # 8 cm off
    config = RefineConfig(
        optimizer=optimizer,
        pyramid_levels=0,
        hidden_point_removal=False,
        parallel=False,
        max_outer=4,
        trust_translation=0.03,
        trust_rotation_deg=1.0,
    )
    seen = []
    pair = RegistrationPair(cam, image, points, intensities)
    result = refine([pair], T_start, config, progress=lambda i, step: seen.append(i))
    region = TrustRegion(T_start, 0.03, 1.0)
    dt, dr = pose_error(invert_T(result.T_camera_lidar), invert_T(T_start))
    assert dt <= 0.03 * (1 + 1e-9) and dr <= 1.0 * (1 + 1e-9), (dt, dr)
    assert result.at_trust_boundary and region.on_boundary(result.T_camera_lidar)
    assert result.moved == pytest.approx((dt, dr))
    assert result.stopped == "" and result.trust_translation == 0.03 and seen
    np.testing.assert_array_equal(result.T_init, T_start)
    # it went towards the truth until the region's edge stopped it (L-BFGS stops on the
    # penalty's kink there, not always at the edge's point nearest the truth)
    assert pose_error(invert_T(result.T_camera_lidar), np.eye(4))[0] < 0.08 - 0.015


def test_trust_region_settings_are_checked_and_the_old_names_still_read():
    from nbcalib.config import CalibrationConfig, config_from_record, set_values

    for bad in ({"trust_translation": -1.0}, {"trust_rotation_deg": -1.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            RefineConfig(**bad)
    with pytest.raises(ValueError, match="trust_rotation_deg"):
        RefineConfig(trust_rotation_deg=180.0)
    # config files and records written before the rename
    config = set_values(CalibrationConfig(), {"refine.max_total_translation": 0.3})
    assert config.refine.trust_translation == 0.3
    record = {"refine": {"max_total_translation": 0.2, "max_total_rotation_deg": 3.0}}
    old = config_from_record(record).refine
    assert (old.trust_translation, old.trust_rotation_deg) == (0.2, 3.0)
    with pytest.raises(ValueError, match="former name"):
        set_values(
            CalibrationConfig(),
            {"refine.max_total_translation": 0.3, "refine.trust_translation": 0.4},
        )


# ------------------------------------------------------------------ a subset of the points


def test_points_per_pixel_samples_a_fixed_nested_subset(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, points, intensities = textured_scene(cam, rng, n=60000, blur=0.8)
    pair = RegistrationPair(cam, image, points, intensities)
    visible = visible_subset(pair, np.eye(4), RefineConfig(points_per_pixel=None))
    assert pair.sample(visible, None) is visible
    assert pair.sample(visible, visible.size) is visible  # room for all: all, as before
    fine, coarse = pair.sample(visible, 20000), pair.sample(visible, 5000)
    for subset, budget in ((fine, 20000), (coarse, 5000)):
        assert abs(subset.size - budget) < 5 * np.sqrt(budget)  # a binomial draw
        assert np.isin(subset, visible).all()
    assert np.isin(coarse, fine).all()  # nested across levels
    np.testing.assert_array_equal(pair.sample(visible, 20000), fine)  # the same every time
    rank = np.empty(int(visible.max()) + 1, dtype=np.int64)
    rank[visible] = np.arange(visible.size)
    assert np.all(np.diff(rank[fine]) > 0)  # in the order of `visible` (pixel order)


def test_points_per_pixel_budget_has_a_floor_and_is_validated(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, points, intensities = textured_scene(cam, rng, n=30000, blur=0.8)
    pair = RegistrationPair(cam, image, points, intensities)
    T = se3_exp(np.array([0.01, 0.0, 0.0, 0.0, 0.005, 0.0]))
    full, counts = build_cost(
        [pair], T, RefineConfig(orientation_classes=False, points_per_pixel=None)
    )
    # 0.01 points per pixel of 320 x 240 would be 768 points; the floor keeps every one of the
    # visible points here, so the cost is the same to the bit
    floored, counts2 = build_cost(
        [pair], T, RefineConfig(orientation_classes=False, points_per_pixel=0.01)
    )
    assert counts == counts2 and floored.value(T) == full.value(T)
    small, _ = build_cost(
        [pair],
        T,
        RefineConfig(orientation_classes=False, points_per_pixel=0.01, min_sampled_points=1000),
    )
    assert small.costs[0].xyz.shape[1] < 0.2 * full.costs[0].xyz.shape[1]
    assert abs(small.value(T) - full.value(T)) < 0.05  # a noisier estimate of the same NID
    bad_values = (
        {"points_per_pixel": 0.0},
        {"points_per_pixel": -1.0},
        {"min_sampled_points": 0},
        {"job_points": 0},
    )
    for bad in bad_values:
        with pytest.raises(ValueError):
            RefineConfig(**bad)


def test_a_job_of_many_pairs_shares_its_point_budget(rng):
    """refine.job_points: each of K pairs uses at most job_points / K points (never fewer than
    min_sampled_points); one pair of an ordinary camera keeps its own budget, and the report's
    per-pair cost of a K-pair job is built on the same share as fine registration's."""
    from nbcalib.registration.costs import point_budget

    cam = example_camera("plumb_bob", 320, 240)
    own = RefineConfig(points_per_pixel=0.25, min_sampled_points=10_000, job_points=None)
    assert point_budget(cam, own, 15) == max(0.25 * 320 * 240, 10_000) == 19_200
    shared = replace(own, job_points=60_000)
    assert point_budget(cam, shared, 1) == 19_200  # one pair: its own budget binds
    assert point_budget(cam, shared, 6) == 10_000  # a sixth of 60 000
    assert point_budget(cam, shared, 15) == 10_000  # never below min_sampled_points
    assert point_budget(cam, replace(shared, points_per_pixel=None), 4) == 15_000
    assert point_budget(cam, replace(own, points_per_pixel=None), 4) is None

    image, points, intensities = textured_scene(cam, rng, n=60000, blur=0.8)
    pair = RegistrationPair(cam, image, points, intensities)
    T = se3_exp(np.array([0.01, 0.0, 0.0, 0.0, 0.005, 0.0]))
    config = RefineConfig(orientation_classes=False, min_sampled_points=5_000, job_points=30_000)
    alone, _ = build_cost([pair], T, config)
    three, _ = build_cost([pair, pair, pair], T, config)
    one_of_three, _ = build_cost([pair], T, config, n_pairs=3)
    n_alone = alone.costs[0].xyz.shape[1]
    assert three.costs[0].xyz.shape[1] == one_of_three.costs[0].xyz.shape[1] < 0.7 * n_alone
    assert one_of_three.value(T) == three.costs[0].value(T)


def test_pairs_costs_built_on_every_core_equal_one_after_another(rng, monkeypatch):
    """build_cost makes each pair's z-buffer, subset and terms on threads (nbcalib._threads):
    the same points, in the same order, and the same cost as one pair after another."""
    from nbcalib import _threads

    cam = example_camera("plumb_bob", 320, 240)
    pairs = []
    for k in range(3):
        image, points, intensities = textured_scene(cam, rng, n=30000, blur=0.8)
        pairs.append(RegistrationPair(cam, image, points, intensities, f"p{k}"))
    T = se3_exp(np.array([0.01, 0.0, 0.0, 0.0, 0.005, 0.0]))
    built = {}
    for workers in (1, 2):
        monkeypatch.setattr(_threads, "WORKERS", workers)
        built[workers] = build_cost(pairs, T, RefineConfig(min_sampled_points=5000))
    (one, counts_one), (two, counts_two) = built[1], built[2]
    assert counts_one == counts_two and len(one.costs) == len(two.costs) == 3
    for a, b in zip(one.costs, two.costs):
        np.testing.assert_array_equal(a.xyz, b.xyz)
    assert one.value_and_grad(T)[0] == two.value_and_grad(T)[0]
    np.testing.assert_array_equal(one.value_and_grad(T)[1], two.value_and_grad(T)[1])
