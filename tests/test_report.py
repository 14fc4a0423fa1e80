"""The quality report: assess() on tiny synthetic pairs, make_report() and `nbcalib report`."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter

from nbcalib import _threads
from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.errors import MissingExtraError
from nbcalib.io.calib_json import read_calib_json
from nbcalib.preprocess.lidar_image import (
    estimate_lidar_fov,
    make_virtual_camera,
    render_lidar_image,
)
from nbcalib.products import PairData
from nbcalib.registration.refine import RefineConfig, RegistrationPair
from nbcalib.report import AssessConfig, assess, rejudge
from nbcalib.transforms import se3_exp, se3_log
from nbcalib.workdir import WorkDir, make_calib
from tests.test_nid import textured_scene
from tests.tolerances import TOL

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def make_pair(seed: int, n: int = 6000, name: str = "") -> RegistrationPair:
    """A 200 x 150 textured image and LiDAR points that see it; the truth is the identity."""
    cam = example_camera("plumb_bob", 200, 150)
    image, points, intensities = textured_scene(cam, np.random.default_rng(seed), n=n, blur=2.0)
    return RegistrationPair(cam, np.round(image * 255).astype(np.uint8), points, intensities, name)


@pytest.fixture(scope="module")
def pair():
    return make_pair(1, name="a")


@pytest.fixture(scope="module")
def quality_at_truth(pair):
    return assess([pair], np.eye(4))


# ------------------------------------------------------------------------------ assess


def test_result_at_the_truth_is_ok_with_finite_uncertainty(quality_at_truth):
    q = quality_at_truth
    assert q.verdict == "ok", q.reasons
    assert q.next_steps == []
    u = q.uncertainty
    values = [*u["translation_cm"], *u["rotation_deg"], u["translation_total_cm"]]
    values.append(u["rotation_total_deg"])
    assert np.all(np.isfinite(values)) and min(values) > 0
    # a textured scene pins the pose well: centimetres and tenths of a degree at most
    assert u["translation_total_cm"] < 5.0 and u["rotation_total_deg"] < 1.0
    # every curve is lowest at (or next to) the result
    centre = q.curve_values.shape[1] // 2
    assert np.all(np.abs(np.argmin(q.curve_values, axis=1) - centre) <= 1)
    assert q.curve_offsets.shape == q.curve_values.shape == (6, 21)
    json.dumps(q.to_dict(), allow_nan=False)


def test_a_result_off_the_minimum_is_suspect(pair):
    T_bad = se3_exp(np.array([0.06, -0.04, 0.0, 0.0, 0.02, -0.01]))  # 7 cm, 1.3 degrees
    q = assess([pair], T_bad)
    assert q.verdict == "suspect"
    assert any(r.startswith("not at a minimum") for r in q.reasons), q.reasons


def test_far_initial_guess_is_suspect(pair):
    T_init = se3_exp(np.array([0.3, 0.0, 0.1, 0.0, 0.0, 0.05]))
    q = assess([pair], np.eye(4), T_init=T_init)
    assert q.verdict == "suspect"
    assert any("far apart" in r for r in q.reasons), q.reasons
    assert q.init_change[0] == pytest.approx(np.linalg.norm([0.3, 0.0, 0.1]), rel=0.1)
    # what to do: start from a measured pose or picked points, said once for its reasons
    assert any("run.manual=picks.json" in step for step in q.next_steps), q.next_steps
    assert len(q.next_steps) == len(set(q.next_steps)) <= len(q.reasons)


def test_a_result_on_the_trust_regions_edge_is_suspect(pair):
    from nbcalib.registration.refine import RefineConfig

    T_init = se3_exp(np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.0]))  # camera centre 5 cm away
    q = assess([pair], np.eye(4), T_init=T_init, config=RefineConfig(trust_translation=0.05))
    assert q.at_trust_boundary and q.trust_region == (0.05, 5.0)
    assert q.verdict == "suspect"
    assert "reached the trust region around the start: moved 0.050 m / 0.00 deg" in " ".join(
        q.reasons
    ), q.reasons
    move = q.to_dict()["move_from_start"]
    assert move["at_trust_boundary"] is True and move["trust_region"]["translation_m"] == 0.05
    # with the default region (0.5 m) the same result is fine
    ok = assess([pair], np.eye(4), T_init=T_init)
    assert not ok.at_trust_boundary and ok.verdict == "ok", ok.reasons


def test_a_move_beyond_the_stated_uncertainties_is_suspect(pair, quality_at_truth):
    u = quality_at_truth.uncertainty["translation_total_cm"] / 100.0
    start_u = 0.5 * u
    allowed = float(np.hypot(start_u, u))
    T_init = se3_exp(np.array([1.5 * allowed, 0.0, 0.0, 0.0, 0.0, 0.0]))
    q = assess([pair], np.eye(4), T_init=T_init, start_uncertainty=(start_u, 5.0))
    assert q.move_allowed[0] == pytest.approx(allowed, rel=1e-9)
    assert q.start_uncertainty_used == ((start_u, 5.0), "stated")
    assert q.verdict == "suspect"
    reason = next(r for r in q.reasons if r.startswith("moved "))
    assert f"moved {150 * allowed:.1f} cm from the start, more than the {100 * allowed:.1f} cm" in (
        reason
    )
    assert "deg" not in reason.split("the start's")[0]  # the rotation stayed within its share
    move = q.to_dict()["move_from_start"]
    assert move["allowed_translation_m"] == pytest.approx(allowed)
    assert move["start_uncertainty"]["source"] == "stated"
    # a move the uncertainties allow is no reason
    near = se3_exp(np.array([0.5 * allowed, 0.0, 0.0, 0.0, 0.0, 0.0]))
    fine = assess([pair], np.eye(4), T_init=near, start_uncertainty=(start_u, 5.0))
    assert not any(r.startswith("moved ") for r in fine.reasons), fine.reasons
    # nothing stated: the trust region (0.5 m / 5 deg) is the start's uncertainty
    unstated = assess([pair], np.eye(4), T_init=T_init)
    assert unstated.start_uncertainty_used == ((0.5, 5.0), "trust region")
    assert unstated.move_allowed[0] > 0.5 and unstated.verdict == "ok", unstated.reasons
    # rejudge keeps the start and recomputes what it allows at the new confidence
    wider = rejudge(q, AssessConfig(confidence=0.999))
    assert wider.start_uncertainty == q.start_uncertainty
    assert wider.move_allowed[0] > q.move_allowed[0]
    with pytest.raises(ValueError, match="uncertainty"):
        assess([pair], np.eye(4), T_init=T_init, start_uncertainty=(-1.0, 1.0))


def test_mismatched_image_is_suspect(pair, rng):
    other = gaussian_filter(rng.random(pair.image.shape), 2.0)
    other = np.round(255 * (other - other.min()) / np.ptp(other)).astype(np.uint8)
    q = assess([replace(pair, image=other)], np.eye(4))
    assert q.verdict == "suspect"
    assert any(r.startswith(("flat cost", "image and LiDAR share")) for r in q.reasons), q.reasons
    assert q.next_steps and all(step.endswith(".") for step in q.next_steps)


def test_too_few_points_is_suspect(pair):
    few = replace(pair, points_lidar=pair.points_lidar[:300], intensities=pair.intensities[:300])
    q = assess([few], np.eye(4))
    assert q.verdict == "suspect"
    assert any(r.startswith("too few points") for r in q.reasons), q.reasons


def test_not_converged_is_a_reason(pair):
    q = assess([pair], np.eye(4), converged=False)
    assert q.verdict == "suspect" and any("did not converge" in r for r in q.reasons)


def test_uncertainty_shrinks_with_more_points(quality_at_truth):
    many = assess([make_pair(1, n=24000)], np.eye(4))
    few, lots = quality_at_truth.uncertainty, many.uncertainty
    assert lots["translation_total_cm"] < few["translation_total_cm"]
    assert lots["rotation_total_deg"] < few["rotation_total_deg"]


def test_uncertainty_shrinks_with_more_pairs(pair, quality_at_truth):
    two = assess([pair, make_pair(2, name="b")], np.eye(4))
    assert two.pair_offsets.shape == (2, 6)
    one, both = quality_at_truth.uncertainty, two.uncertainty
    assert both["translation_total_cm"] < one["translation_total_cm"]
    assert both["rotation_total_deg"] < one["rotation_total_deg"]


def test_rejudge_scales_the_intervals(quality_at_truth):
    # the curvature part alone (the restarts' part has its own scale)
    q1 = rejudge(quality_at_truth, AssessConfig(scale=1.0, restarts=0))
    q4 = rejudge(quality_at_truth, AssessConfig(scale=4.0, restarts=0))
    u1, u4 = q1.uncertainty, q4.uncertainty
    np.testing.assert_allclose(q4.sigma, 2.0 * q1.sigma, **TOL["report_rescaled_sigma"])
    np.testing.assert_allclose(
        [u4["translation_total_cm"], u4["rotation_total_deg"]],
        [2.0 * u1["translation_total_cm"], 2.0 * u1["rotation_total_deg"]],
        **TOL["report_rescaled_sigma"],
    )


def test_jackknife_of_blocks_is_the_spread_of_their_optima():
    # blocks with the same curvature and their own optima c_b: the summed cost's minimum is their
    # mean, and the delete-a-block jackknife gives the variance of a mean, s^2 / B (Efron-Stein)
    from nbcalib.report.uncertainty import _jackknife

    rng = np.random.default_rng(3)
    B, H0 = 12, np.diag([4e4, 5e4, 3e4, 9e5, 8e5, 7e5])
    optima = rng.normal(0.0, [0.01, 0.02, 0.01, 1e-3, 2e-3, 1e-3], (B, 6))
    hess = np.repeat(H0[None], B, axis=0)
    grads = -(optima - optima.mean(axis=0)) @ H0  # gradients at the summed cost's minimum
    spans = np.full(6, 1.0)
    cov = _jackknife(grads, hess, spans)
    np.testing.assert_allclose(cov, np.cov(optima.T, ddof=1) / B, rtol=1e-9, atol=1e-15)
    assert _jackknife(grads[:2], hess[:2], spans) is None  # too few blocks to say anything


@pytest.mark.parametrize("spread", [1.0, 5.0])
def test_the_pair_test_keeps_its_false_alarm_rate_for_many_pairs(spread):
    # agreeing pairs whose single-shot biases scatter at the floor, or at five times it and
    # unequally over the axes: the chance that any of K pairs is called elsewhere stays below
    # 1 - q and does not grow with K (two pairs cannot know a spread above the floor; from five
    # on the other pairs' spread stands in)
    from nbcalib.report.verdict import pairs_elsewhere

    rng = np.random.default_rng(4)
    q, floor = 0.99, np.array([0.003] * 3 + [1e-3] * 3)
    shape = np.ones(6)
    if spread > 1.0:
        shape = np.array([1.5, 1.0, 0.5, 1.5, 1.0, 0.5]) / np.sqrt(np.mean([1.5**2, 1, 0.25]))
    rates = {}
    for k in (2, 5, 15) if spread == 1.0 else (5, 15):
        own = np.repeat(np.diag((0.5 * floor) ** 2)[None], k, axis=0)
        trials = 600
        x = rng.normal(0.0, spread * floor * shape, (trials, k, 6))
        x += rng.normal(0.0, 0.5 * floor, (trials, k, 6))
        x -= x.mean(axis=1, keepdims=True)  # offsets from the joint result
        rates[k] = np.mean([max(pairs_elsewhere(o, own, floor, q)) > 1.0 for o in x])
        # at the floor the test's level holds; above it on one axis more than the others, a
        # spread pooled over the axes of a kind is a little small at times (2.3 % at K = 5)
        assert rates[k] <= (1.0 if spread == 1.0 else 3.0) * (1.0 - q) + 0.01, rates
    assert rates[15] <= rates[5] + 0.01, rates


@pytest.mark.parametrize("n_pairs", [2, 5, 15])
def test_the_pair_test_names_a_pair_far_off(n_pairs):
    from nbcalib.report.verdict import pairs_elsewhere

    rng = np.random.default_rng(n_pairs)
    floor = np.array([0.003] * 3 + [1e-3] * 3)
    own = np.repeat(np.diag((0.5 * floor) ** 2)[None], n_pairs, axis=0)
    x = rng.normal(0.0, 0.5 * floor, (n_pairs, 6))
    x[1, 2] += 0.10  # a pair 10 cm off along z: a wrong image, a time offset
    x -= x.mean(axis=0)
    ratios = pairs_elsewhere(x, own, floor, 0.999)
    if n_pairs == 2:  # which of two is off no test can say: both are named
        assert min(ratios) > 1.0, ratios
    else:
        assert ratios[1] > 1.0 and max(np.delete(ratios, 1)) < 1.0, ratios
    with pytest.raises(ValueError, match="two pairs"):
        pairs_elsewhere(x[:1], own[:1], floor, 0.999)


def test_the_pair_test_with_no_uncertainty_at_all_flags_any_difference():
    """Both floors set to 0 and no curvature: identical pairs agree, a different one does not."""
    from nbcalib.report.verdict import pairs_elsewhere

    own = np.zeros((3, 6, 6))
    same = np.zeros((3, 6))
    assert pairs_elsewhere(same, own, np.zeros(6), 0.999) == [0.0, 0.0, 0.0]
    apart = same.copy()
    apart[2, 0] = 0.01
    ratios = pairs_elsewhere(apart, own, np.zeros(6), 0.999)
    assert not np.isnan(ratios).any() and ratios[2] > 1.0, ratios


def test_image_regions_add_their_spread_to_the_uncertainty():
    many = make_pair(1, n=24000)
    q = assess([many], np.eye(4))
    assert len(q.block_pair) >= 3 and set(q.block_pair.tolist()) == {0}
    # the blocks are the parts of the pair's cost: their gradients sum to its gradient
    np.testing.assert_allclose(q.block_gradients.sum(axis=0), q.pair_gradients[0], atol=1e-9)
    assert "jackknife" in q.uncertainty["method"]
    without = rejudge(q, AssessConfig(jackknife_scale=0.0)).uncertainty
    assert q.uncertainty["translation_total_cm"] > without["translation_total_cm"]
    assert q.uncertainty["rotation_total_deg"] > without["rotation_total_deg"]


def test_with_the_structure_term_the_hessian_is_the_whole_costs(monkeypatch):
    # the regional terms' Hessian comes from their blocks, the structure term's from its own
    # differences: together the whole cost's, without measuring the regions twice
    from nbcalib.registration.refine import RefineConfig, build_cost
    from nbcalib.report import quality as quality_module

    many = make_pair(1, n=24000)
    config = RefineConfig(structure_weight=0.5)
    seen = []
    true_hessian = quality_module._hessian

    def spy(cost, T, steps, blocks=None):
        H = true_hessian(cost, T, steps, blocks)
        seen.append((cost, H))
        return H

    monkeypatch.setattr(quality_module, "_hessian", spy)
    q = assess([many], np.eye(4), config=config)
    (rest, H), whole_cost = (
        seen[0],
        build_cost([many], np.eye(4), replace(config, optimizer="lbfgs"))[0],
    )
    assert rest is not None and len(rest.costs) < len(whole_cost.costs) and len(q.block_pair) >= 3
    whole = true_hessian(whole_cost, np.eye(4), np.array([0.005] * 3 + [np.radians(0.1)] * 3))
    np.testing.assert_allclose(H, whole, rtol=1e-6, atol=1e-9 * np.abs(whole).max())


def test_saved_quality_is_judged_again_to_the_same_verdict(tmp_path, quality_at_truth):
    from nbcalib.report import load_quality

    quality_at_truth.save(tmp_path / "quality.npz")
    loaded = load_quality(tmp_path / "quality.npz")
    assert loaded.config == quality_at_truth.config and loaded.names == quality_at_truth.names
    again = rejudge(loaded, AssessConfig(scale=3.0))
    before = rejudge(quality_at_truth, AssessConfig(scale=3.0))
    np.testing.assert_array_equal(again.covariance, before.covariance)
    assert again.verdict == before.verdict and again.reasons == before.reasons
    assert again.uncertainty == before.uncertainty


class QuadraticCost:
    """A stand-in for an NID cost: ``0.5 delta^T B delta`` of ``delta = log(T)``."""

    def __init__(self, B):
        self.B = np.asarray(B, dtype=np.float64)

    def value(self, T):
        d = se3_log(T)
        return 0.5 * float(d @ self.B @ d)


STEPS = np.array([0.005] * 3 + [np.radians(0.1)] * 3)


def _with_eigenvalue(H, direction, value):
    """``H`` with its eigenvalue along the unit eigenvector ``direction`` set to ``value``."""
    return H + (value - direction @ H @ direction) * np.outer(direction, direction)


def test_a_direction_without_curvature_is_measured_again_from_the_values():
    from nbcalib.report.uncertainty import _remeasure_flat_directions

    B = np.diag([40.0, 60.0, 20.0, 9e4, 8e4, 7e4])
    d = np.zeros(6)
    d[2] = 1.0  # tz: B says 20, the (noisy) gradient differences said -3
    H, n_again = _remeasure_flat_directions(
        QuadraticCost(B), np.eye(4), _with_eigenvalue(B, d, -3.0), STEPS, 0.0, 16
    )
    assert n_again == 1
    np.testing.assert_allclose(H, B, rtol=1e-9, atol=1e-9)  # a quadratic: exact at m = 1


def test_a_direction_the_values_do_not_rise_along_stays_flat():
    from nbcalib.report.uncertainty import _remeasure_flat_directions

    B = np.diag([40.0, 60.0, 0.0, 9e4, 8e4, 7e4])  # no rise along tz at any scale
    d = np.zeros(6)
    d[2] = 1.0
    H, n_again = _remeasure_flat_directions(
        QuadraticCost(B), np.eye(4), _with_eigenvalue(B, d, -3.0), STEPS, 0.0, 16
    )
    assert n_again == 1
    assert np.linalg.eigvalsh(H)[0] == pytest.approx(-3.0)
    # with the re-measurement switched off nothing changes
    H_off, n_off = _remeasure_flat_directions(
        QuadraticCost(B), np.eye(4), _with_eigenvalue(B, d, -3.0), STEPS, 0.0, 0
    )
    assert n_off == 0 and np.linalg.eigvalsh(H_off)[0] == pytest.approx(-3.0)


def test_a_noisy_negative_curvature_at_a_good_result_is_not_a_flat_cost(pair, monkeypatch):
    # on demo-sized pairs the gradient differences of a weak direction are within the cost's
    # sub-pixel roughness and came out negative on good results: simulate that on the smallest
    # eigen-direction of the real Hessian, whose NID values do rise
    from nbcalib.report import quality as quality_module

    true_hessian = quality_module._hessian

    def noisy_hessian(cost, T, steps, blocks=None):
        H = true_hessian(cost, T, steps, blocks)
        w, V = np.linalg.eigh(H)
        return _with_eigenvalue(H, V[:, 0], -0.5 * abs(w[0]))

    reference = assess([pair], np.eye(4))
    monkeypatch.setattr(quality_module, "_hessian", noisy_hessian)
    q = assess([pair], np.eye(4))
    assert q.pair_remeasured.tolist() == [1]
    assert q.verdict == "ok", q.reasons
    u, ref = q.uncertainty, reference.uncertainty
    # the re-measured curvature (second differences of values) is of the size of the true one
    assert 0.5 < u["translation_total_cm"] / ref["translation_total_cm"] < 2.0
    assert 0.5 < u["rotation_total_deg"] / ref["rotation_total_deg"] < 2.0


def test_per_pair_optima_take_no_step_along_re_measured_directions(pair, monkeypatch):
    # the per-pair optimum is the minimum of the gradient's quadratic model; along a direction
    # whose gradient differences showed no positive curvature that model has none, even when the
    # values (and so the uncertainty) give the direction a curvature
    from nbcalib.report import quality as quality_module
    from nbcalib.report.uncertainty import _newton_inverse

    true_hessian = quality_module._hessian
    flipped = []

    def noisy_hessian(cost, T, steps, blocks=None):
        H = true_hessian(cost, T, steps, blocks)
        v = np.linalg.eigh(H)[1][:, 0]
        flipped.append(v)
        return _with_eigenvalue(H, v, -abs(v @ H @ v))

    monkeypatch.setattr(quality_module, "_hessian", noisy_hessian)
    monkeypatch.setattr(_threads, "WORKERS", 1)  # the pairs in order: flipped[k] is pair k's
    T = se3_exp(np.array([0.01, -0.005, 0.008, 0.002, 0.0, -0.001]))  # off the minimum
    q = assess([pair, make_pair(2, name="b")], T)
    assert q.pair_remeasured.tolist() == [1, 1]
    for k, v in enumerate(flipped):
        assert v @ q.pair_hessians[k] @ v > 0.0  # the uncertainty uses the values' curvature
        assert abs(q.pair_offsets[k] @ v) < 1e-9
        # a step through the re-measured Hessian would move along v
        n = q.pixels_covered[k]
        step = -(_newton_inverse(n * q.pair_hessians[k]) @ (n * q.pair_gradients[k]))
        assert abs(step @ v) > 1e-5


def test_pairs_judged_on_every_core_equal_one_after_another(pair, monkeypatch):
    """A many-pair report measures each pair's cost, Hessians and curves on threads
    (nbcalib._threads): every figure equals the one-pair-at-a-time report's to the bit."""
    T = se3_exp(np.array([0.01, -0.005, 0.008, 0.002, 0.0, -0.001]))
    pairs = [pair, make_pair(2, name="b"), make_pair(3, name="c")]
    judged = {}
    for workers in (1, 2):
        monkeypatch.setattr(_threads, "WORKERS", workers)
        judged[workers] = assess(pairs, T).to_dict()
    assert json.dumps(judged[1], sort_keys=True) == json.dumps(judged[2], sort_keys=True)


def test_pixels_covered_from_the_z_buffer_equal_projecting_the_visible_points(pair):
    """The report counts a pair's pixels from the z-buffer's own pixels: the same count as
    projecting the visible points again and rounding them to pixels."""
    from nbcalib.registration.refine import visible_subset
    from nbcalib.report.uncertainty import _pixels_covered

    config = RefineConfig()
    for T in (np.eye(4), se3_exp(np.array([0.03, -0.02, 0.01, 0.004, -0.003, 0.002]))):
        keep = visible_subset(pair, T, config)
        uv, valid = pair.camera.project(pair.points_lidar[keep] @ T[:3, :3].T + T[:3, 3])
        pixels = np.floor(uv[valid] + 0.5).astype(np.int64)
        expected = len(np.unique(pixels[:, 1] * pair.camera.width + pixels[:, 0]))
        assert _pixels_covered(pair, T, config) == expected > 1000


def test_assess_rejects_programming_errors(pair):
    with pytest.raises(ValueError, match="at least one"):
        assess([], np.eye(4))
    with pytest.raises(ValueError):
        assess([pair], np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="curve_samples"):
        AssessConfig(curve_samples=10)
    with pytest.raises(ValueError, match="max_curvature_scale"):
        AssessConfig(max_curvature_scale=-1)


def test_lidar_edge_points_mark_the_near_side_of_a_depth_step():
    from nbcalib.report.figures import lidar_edge_points

    index = np.arange(8 * 10, dtype=np.int32).reshape(8, 10)
    index[:, 9] = -1  # an empty column: no edge against empty pixels
    ranges = np.where(np.arange(10) < 5, 2.0, 5.0)[None, :].repeat(8, axis=0).ravel()
    points = np.column_stack([ranges, np.zeros_like(ranges), np.zeros_like(ranges)])
    flat = np.full((8, 10), 128, dtype=np.uint8)  # no intensity edges
    edges = lidar_edge_points(flat, index, points)
    np.testing.assert_array_equal(edges, index[:, 4])  # column 4: the near side of the step


# ------------------------------------------------------------------------------ work directory


@pytest.fixture
def workdir(tmp_path, pair):
    """A finished work directory: one pair, an initial guess and a (true) result."""
    vcam, T_vcam_lidar = make_virtual_camera(estimate_lidar_fov(pair.points_lidar))
    lidar_image = render_lidar_image(vcam, T_vcam_lidar, pair.points_lidar, pair.intensities)
    work = WorkDir(tmp_path / "work")
    work.prepare()
    work.write_pair(
        PairData("000000", pair.image, pair.points_lidar, pair.intensities, lidar_image)
    )
    calib = make_calib(pair.camera, ["000000"])
    calib.set_T_camera_lidar("init_T_lidar_camera", se3_exp(np.array([0.03, 0, 0, 0, 0.01, 0])))
    calib.set_T_camera_lidar("T_lidar_camera", np.eye(4))
    work.write_calib(calib)
    return work


def test_report_writes_html_figures_and_calib_json(workdir, capsys):
    before = read_calib_json(workdir.calib_path)
    assert main(["report", str(workdir.path)]) == 0
    out = capsys.readouterr().out
    assert "verdict: ok" in out and "index.html" in out
    folder = workdir.path / "report"
    page = (folder / "index.html").read_text()
    from nbcalib.report import load_quality

    assert load_quality(folder / "quality.npz").verdict == "ok"  # the material to judge again
    pngs = sorted(p.name for p in folder.glob("*.png"))
    assert pngs == [
        "alignment_000000.png",
        "edges_000000.png",
        "nid_curves.png",
        "overlay_000000.png",
        "pairs_uncertainty.png",
    ]
    for name in pngs:
        assert (folder / name).read_bytes()[:8] == PNG_MAGIC
        assert f'src="{name}"' in page
    assert "Verdict" in page and "Uncertainty" in page
    after = read_calib_json(workdir.calib_path)
    assert (after.camera, after.meta, after.results) == (before.camera, before.meta, before.results)
    quality = after.to_dict()["nbcalib"]["quality"]
    assert quality["verdict"] == "ok" and quality["report"] == "report/index.html"
    assert quality["uncertainty"]["translation_total_cm"] > 0
    assert not list(workdir.path.glob(".report*"))  # no temporary folders left


def test_report_without_matplotlib_has_numbers_only(workdir, monkeypatch):
    import nbcalib.report.html as report_html

    def missing(module, extra):
        raise MissingExtraError(module, extra)

    monkeypatch.setattr(report_html, "require", missing)
    from nbcalib.pipeline import make_report

    report = make_report(workdir.path)
    page = report.html_path.read_text()
    assert "numbers only" in page and "nbcalib[viz]" in page
    assert report.figures == [] and not list(report.html_path.parent.glob("*.png"))


def test_a_failed_report_leaves_the_previous_one_whole(workdir, monkeypatch):
    import nbcalib.report.figures as figures
    from nbcalib.pipeline import make_report

    first = make_report(workdir.path)
    page = first.html_path.read_text()

    def broken(quality):
        raise RuntimeError("disk full")

    monkeypatch.setattr(figures, "nid_curves", broken)
    with pytest.raises(RuntimeError, match="disk full"):
        make_report(workdir.path)
    assert first.html_path.read_text() == page
    assert not list(workdir.path.glob(".report*"))


def test_report_flags_a_garbage_result(workdir):
    from nbcalib.pipeline import make_report

    calib = read_calib_json(workdir.calib_path)
    calib.set_T_camera_lidar("T_lidar_camera", se3_exp(np.array([0.07, 0, 0.03, 0, 0.02, 0])))
    workdir.write_calib(calib)
    report = make_report(workdir.path)
    assert report.verdict == "suspect" and report.reasons
    assert "suspect" in report._repr_html_()
    page = report.html_path.read_text()
    assert "What to do next" in page and report.quality.next_steps
    stored = read_calib_json(workdir.calib_path).to_dict()["nbcalib"]["quality"]
    assert stored["next_steps"] == report.quality.next_steps


@pytest.mark.parametrize(
    "setup, message",
    [
        ("no_result", "run nbcalib calibrate first"),
        ("no_calib", "run 'nbcalib preprocess' first"),
        ("no_dir", "work directory not found"),
        ("no_cloud", "000000.ply"),
    ],
)
def test_report_user_errors_exit_2(workdir, capsys, setup, message):
    path = workdir.path
    if setup == "no_result":
        calib = read_calib_json(workdir.calib_path)
        del calib.results["T_lidar_camera"]
        workdir.write_calib(calib)
    elif setup == "no_calib":
        workdir.calib_path.unlink()
    elif setup == "no_dir":
        path = path / "missing"
    elif setup == "no_cloud":
        workdir.cloud_path("000000").unlink()
    assert main(["report", str(path)]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1
    assert not (workdir.path / "report").exists()


def test_report_strict_exit_status(workdir, capsys):
    calib = read_calib_json(workdir.calib_path)
    calib.set_T_camera_lidar("T_lidar_camera", se3_exp(np.array([0.07, 0, 0.03, 0, 0.02, 0])))
    workdir.write_calib(calib)
    assert main(["report", str(workdir.path), "--strict"]) == 3  # without --strict: 0 (above)
    assert "next: " in capsys.readouterr().out  # the printout says what to do


def test_an_uncertainty_no_rig_can_have_is_called_unbounded():
    from nbcalib.report.quality import format_bound

    assert format_bound(0.5234, "cm") == "0.52 cm"
    assert format_bound(0.03123, "deg") == "0.031 deg"
    for value, unit in ((7.97e152, "cm"), (8472.88, "deg"), (float("inf"), "cm")):
        assert format_bound(value, unit).startswith("unbounded")


def test_lidar_edges_of_a_sparse_image_are_its_edges_not_its_points():
    """A rosette-like image (a tenth of the pixels filled) of two flat halves: the edge points
    are those along the step, not every point against its empty neighbours."""
    from nbcalib.report.figures import lidar_edge_points

    rng = np.random.default_rng(0)
    h, w = 120, 160
    filled = rng.random((h, w)) < 0.1
    intensity = np.where(np.arange(w)[None, :] < w // 2, 40, 200).astype(np.uint8)
    intensity = np.where(filled, intensity, 0).astype(np.uint8)
    index = np.full((h, w), -1, dtype=np.int32)
    index[filled] = np.arange(filled.sum())
    points = np.column_stack([np.ones(filled.sum()) * 5.0, np.zeros((filled.sum(), 2))])
    edges = lidar_edge_points(intensity, index, points)
    cols = np.argwhere(filled)[:, 1][edges]
    assert 0 < len(edges) < 0.25 * filled.sum()
    assert np.all(np.abs(cols - w // 2) <= 8)


# ------------------------------------------------------------------------------ figures


def test_rasterised_points_colour_their_pixels_and_leave_the_rest():
    from nbcalib.report.figures import rasterise_points

    image = np.full((10, 12, 3), 50, dtype=np.uint8)
    uv = np.array([[2.0, 3.0], [7.4, 6.6], [11.2, 9.3], [-3.0, 4.0], [np.nan, 1.0]])
    colours = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9], [9, 9, 9]], np.uint8)
    out = rasterise_points(image, uv, colours)
    assert out is not image and np.all(image == 50)  # drawn into a copy
    expected = image.copy()
    expected[3, 2] = (255, 0, 0)
    expected[7, 7] = (0, 255, 0)  # the pixel the point falls in: row 7 (6.6), column 7 (7.4)
    expected[9, 11] = (0, 0, 255)  # outside and NaN points are left out
    np.testing.assert_array_equal(out, expected)
    # 2 x 2 dots: the block whose centre is nearest to the point
    out = rasterise_points(image, uv[1:2], colours[1], size=2)
    assert {tuple(p) for p in np.argwhere(out[..., 1] == 255)} == {(6, 7), (6, 8), (7, 7), (7, 8)}
    assert np.all(out[out[..., 1] != 255] == 50)
    # 3 x 3 dots centred on the point, cut at the border
    out = rasterise_points(image, np.array([[0.0, 5.0]]), colours[0], size=3)
    assert {tuple(p) for p in np.argwhere(out[..., 0] == 255)} == {
        (r, c) for r in (4, 5, 6) for c in (0, 1)
    }


def test_rasterised_nearer_points_cover_farther_ones():
    from nbcalib.report.figures import rasterise_points

    image = np.zeros((6, 6, 3), dtype=np.uint8)
    uv = np.array([[2.0, 2.0], [2.2, 1.9], [3.0, 2.0]])
    colours = np.array([[200, 0, 0], [0, 200, 0], [0, 0, 200]], np.uint8)
    # the near point (green) wins the pixel it shares with the red one, whichever comes first;
    # the far blue point keeps its own pixel
    for order in ([0, 1, 2], [2, 1, 0]):
        out = rasterise_points(image, uv[order], colours[order], np.array([5.0, 2.0, 9.0])[order])
        assert tuple(out[2, 2]) == (0, 200, 0)
        assert tuple(out[2, 3]) == (0, 0, 200)
    out = rasterise_points(image, uv, colours, np.array([5.0, 2.0, 9.0]), size=3)
    # the near green dot covers rows and columns 1-3, over the red one and part of the blue
    assert np.all(out[1:4, 1:4] == (0, 200, 0))
    assert np.all(out[1:4, 4] == (0, 0, 200))  # the rest of the blue dot
    assert not np.any(out[..., 0])  # nothing left of the red dot


def _png_pixels(data: bytes) -> np.ndarray:
    from io import BytesIO

    from PIL import Image

    return np.asarray(Image.open(BytesIO(data)).convert("RGB"))


def test_overlay_panels_show_the_points_in_their_colours_on_the_image():
    pytest.importorskip("matplotlib")
    import matplotlib as mpl

    from nbcalib.report import figures as fg

    cam = example_camera("plumb_bob", 200, 150)
    image = np.full((150, 200), 128, dtype=np.uint8)  # blank grey
    uv = np.array([[30.0, 40.0], [100.0, 75.0], [170.0, 120.0], [60.0, 130.0]])
    ranges = np.array([2.0, 3.0, 5.0, 4.0])
    intensities = np.array([0.1, 0.9, 0.5, 0.3])
    bearings = cam.unproject(uv)
    points = bearings / np.linalg.norm(bearings, axis=1, keepdims=True) * ranges[:, None]
    png = fg.overlays(cam, image, points, intensities, [("result", np.eye(4), np.arange(4))])
    pixels = _png_pixels(png)
    scale = fg.OVERLAY_PANEL_WIDTH / cam.width
    panel_h = round(fg.OVERLAY_PANEL_WIDTH * cam.height / cam.width)
    centres = np.floor((uv + 0.5) * scale).astype(int)  # the dots' centre pixels (column, row)
    column_w = fg.OVERLAY_PANEL_WIDTH + sum(fg._COLORBAR_PX) + fg._MARGIN_PX
    top = fg._MARGIN_PX + fg._TITLE_PX
    for col, (cmap, norm, values) in enumerate(
        [
            ("turbo", mpl.colors.Normalize(0.0, np.percentile(ranges, 98)), ranges),
            ("viridis", mpl.colors.Normalize(0.0, 1.0), intensities),
        ]
    ):
        left = fg._MARGIN_PX + col * column_w
        panel = pixels[top : top + panel_h, left : left + fg.OVERLAY_PANEL_WIDTH]
        expected = mpl.colormaps[cmap](norm(values), bytes=True)[:, :3]
        near = np.zeros(panel.shape[:2], dtype=bool)
        for (c, r), colour in zip(centres, expected):
            np.testing.assert_array_equal(
                panel[r - 1 : r + 2, c - 1 : c + 2], np.broadcast_to(colour, (3, 3, 3))
            )
            near[r - 2 : r + 3, c - 2 : c + 3] = True
        assert np.all(panel[~near] == 128)  # everywhere else: the image


def test_edge_overlay_draws_the_edge_points_in_orange():
    pytest.importorskip("matplotlib")
    from nbcalib.report import figures as fg

    cam = example_camera("plumb_bob", 200, 150)
    image = np.full((150, 200), 128, dtype=np.uint8)  # no edges: a black background
    uv = np.array([[30.0, 40.0], [100.0, 75.0], [170.0, 120.0]])
    bearings = cam.unproject(uv)
    points = 3.0 * bearings / np.linalg.norm(bearings, axis=1, keepdims=True)
    poses = [("initial guess", np.eye(4), np.arange(3)), ("result", np.eye(4), np.arange(2))]
    pixels = _png_pixels(fg.edge_overlay(cam, image, points, np.array([0, 1, 2]), poses))
    scale = fg.EDGE_PANEL_WIDTH / cam.width
    panel_h = round(fg.EDGE_PANEL_WIDTH * cam.height / cam.width)
    centres = np.floor((uv + 0.5) * scale).astype(int)
    top = fg._MARGIN_PX + fg._TITLE_PX
    for k, n_drawn in enumerate((3, 2)):
        left = fg._MARGIN_PX + k * (fg.EDGE_PANEL_WIDTH + fg._MARGIN_PX)
        panel = pixels[top : top + panel_h, left : left + fg.EDGE_PANEL_WIDTH]
        orange = np.all(panel == (255, 127, 14), axis=2)
        for i, (c, r) in enumerate(centres):
            assert orange[r, c] == (i < n_drawn)
        assert np.all(panel[~orange] == 0)


def test_the_parallel_kernels_give_the_report_of_the_serial_ones(
    pair, quality_at_truth, monkeypatch
):
    """Terms of PARALLEL_MIN_POINTS points or more use the parallel kernels: the same report."""
    import nbcalib.report.quality as quality

    monkeypatch.setattr(quality, "PARALLEL_MIN_POINTS", 1)  # every term parallel
    q = assess([pair], np.eye(4))
    serial = quality_at_truth  # these pairs are far below the threshold: serial
    assert q.verdict == serial.verdict and q.reasons == serial.reasons
    np.testing.assert_allclose(q.curve_values, serial.curve_values, rtol=0, atol=1e-12)
    np.testing.assert_allclose(q.hessian, serial.hessian, rtol=1e-8, atol=1e-9)
    for key in ("translation_total_cm", "rotation_total_deg"):
        assert q.uncertainty[key] == pytest.approx(serial.uncertainty[key], rel=1e-8)


# ------------------------------------------------------------------------------ restarts


def test_restart_starts_are_exactly_the_stated_distance_away():
    from nbcalib.report.uncertainty import restart_starts
    from nbcalib.transforms import invert_T, pose_error

    T = se3_exp([0.1, -0.2, 0.3, 0.2, -0.1, 0.05])
    starts = restart_starts(T, 5, 0.05, 1.0)
    assert len(starts) == 5
    for T0 in starts:
        dt, dr = pose_error(invert_T(T0), invert_T(T))
        assert dt == pytest.approx(0.05, abs=1e-9) and dr == pytest.approx(1.0, abs=1e-9)
    again = restart_starts(T, 5, 0.05, 1.0)  # seeded: the same result, the same starts
    np.testing.assert_array_equal(np.array(starts), np.array(again))
    # fewer restarts are the first of more: a report can be judged again with fewer
    np.testing.assert_array_equal(np.array(restart_starts(T, 2, 0.05, 1.0)), np.array(starts[:2]))


def test_restarts_at_a_well_posed_result_come_back_and_stay_ok(quality_at_truth):
    q = quality_at_truth
    assert q.restart_offsets.shape == (AssessConfig().restarts, 6)
    # a textured synthetic pair has one minimum: every restart ends where the result is
    assert np.degrees(np.linalg.norm(q.restart_offsets[:, 3:], axis=1)).max() < 0.05
    assert np.linalg.norm(q.restart_offsets[:, :3], axis=1).max() < 0.005
    assert q.verdict == "ok" and "restarts" in q.uncertainty["method"]


def test_restarts_that_end_elsewhere_widen_the_interval_and_make_it_suspect(quality_at_truth):
    c = AssessConfig()
    base = rejudge(quality_at_truth, replace(c, restarts=0))
    assert base.verdict == "ok" and "restarts" not in base.uncertainty["method"]
    ends = np.zeros((4, 6))
    ends[:, 4] = np.radians([0.5, -0.4, 0.6, 0.3])  # a shallow minimum per start, about y
    ends[:, 0] = [0.02, -0.03, 0.01, 0.04]
    moved = replace(quality_at_truth, restart_offsets=ends)
    q = rejudge(moved, c)
    # their spread joins the covariance, times restart_scale
    added = c.restart_scale * (ends**2).mean(axis=0)
    np.testing.assert_allclose(q.sigma**2 - base.sigma**2, added, rtol=1e-9, atol=1e-15)
    assert q.verdict == "suspect"
    assert any("depends on where registration starts" in r for r in q.reasons), q.reasons
    assert any("run.init=" in s for s in q.next_steps)
    # a median end within the limit is no reason; restarts=0 judges as if there were none
    near = replace(quality_at_truth, restart_offsets=ends * 0.1)
    assert not any("registration starts" in r for r in rejudge(near, c).reasons)
    assert rejudge(moved, replace(c, restarts=0)).verdict == "ok"
    # judged with two restarts: the first two ends only (those two restarts would find)
    two = rejudge(moved, replace(c, restarts=2))
    added = c.restart_scale * (ends[:2] ** 2).mean(axis=0)
    np.testing.assert_allclose(two.sigma**2 - base.sigma**2, added, rtol=1e-9, atol=1e-15)
    assert two.restart_offsets.shape == (2, 6)


def test_restarts_score_restart_points_of_the_pair(pair, monkeypatch):
    """Each restart scores AssessConfig.restart_points points (never more than fine
    registration's own budget); None: fine registration's budget as it is."""
    import nbcalib.report.uncertainty as quality_module

    budgets = []
    real = quality_module.refine

    def spy(pairs, T0, config, **kwargs):
        pixels = pairs[0].camera.width * pairs[0].camera.height
        budgets.append(max(config.points_per_pixel * pixels, config.min_sampled_points))
        return real(pairs, T0, config, **kwargs)

    monkeypatch.setattr(quality_module, "refine", spy)
    refine_config = RefineConfig(points_per_pixel=0.25, min_sampled_points=50_000)
    own = max(0.25 * pair.camera.width * pair.camera.height, 50_000)
    for points, want in ((1000, 1000), (10**9, own), (None, own)):
        budgets.clear()
        assess([pair], np.eye(4), config=refine_config, assess_config=AssessConfig(
            restarts=2, restart_points=points))  # fmt: skip
        assert budgets == pytest.approx([want, want])
    with pytest.raises(ValueError, match="restart_points"):
        AssessConfig(restart_points=0)


def test_several_pairs_are_not_restarted():
    """Their own spread measures a shot's bias; restarting many pairs would cost minutes."""
    q = assess([make_pair(1, name="a"), make_pair(2, name="b")], np.eye(4))
    assert q.restart_offsets.shape == (0, 6) and "restarts" not in q.uncertainty["method"]
