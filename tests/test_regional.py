"""The regional NID: grouped histograms against the reference, regions, the cost seam."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.camera import example_camera
from nbcalib.kernels import nid as k
from nbcalib.reference import nid as ref
from nbcalib.registration.config import COSTS, RefineConfig
from nbcalib.registration.costs import build_cost
from nbcalib.registration.costs.regional import median_cut_regions
from nbcalib.registration.nid import GroupedNIDCost, NIDCost, quantise
from nbcalib.registration.refine import RegistrationPair, refine
from nbcalib.transforms import pose_error, se3_exp
from tests.numba_regions import parallel_regions
from tests.test_nid import nasty_points, textured_scene
from tests.tolerances import TOL


def _grouped(rng, cam, n_groups, n=1500, bins=8):
    pts = nasty_points(cam, rng, n=n)
    point_bins = rng.integers(0, bins, len(pts)).astype(np.uint8)
    # sorted by group, as GroupedNIDCost stores them; group sizes uneven, one group empty
    groups = np.sort(rng.integers(0, n_groups, len(pts)))
    groups[groups == 1] = 2
    image_bins = rng.integers(0, bins, (cam.height, cam.width)).astype(np.uint8)
    return pts, point_bins, groups, image_bins


@pytest.mark.parametrize("model", ["plumb_bob", "fisheye", "equirectangular"])
def test_stacked_histograms_are_each_groups_own(model, rng):
    """Stacked rows (group * bins + LiDAR bin) give every group its reference histogram."""
    cam = example_camera(model, 160, 120 if model != "equirectangular" else 80)
    bins, n_groups = 8, 5
    pts, point_bins, groups, image_bins = _grouped(rng, cam, n_groups, bins=bins)
    rows = k.grouped_rows(groups, point_bins, bins)
    T = se3_exp(np.array([0.01, -0.02, 0.03, 0.01, 0.02, -0.01]))
    padded = k.padded_image_bins(image_bins, bins)
    xyz = np.ascontiguousarray(pts.T)
    for parallel in (False, True):
        hard = k.joint_hist_hard(
            cam.model_id, cam.params, T, xyz, rows, image_bins, bins,
            parallel=parallel, padded=padded, groups=n_groups,
        )  # fmt: skip
        kernel = k._joint_hist_smooth_parallel if parallel else k._joint_hist_smooth
        smooth, dsmooth, count = kernel(
            cam.model_id, cam.params, T, xyz, rows, image_bins, bins, n_groups * bins,
            k.N_CHUNKS, True, 0, 1.0,
        )  # fmt: skip
        for g in range(n_groups):
            sel = groups == g
            block = slice(g * bins, (g + 1) * bins)
            args = (cam, T, pts[sel], point_bins[sel], image_bins, bins)
            assert np.array_equal(hard[block], ref.joint_histogram_hard(*args))
            assert_allclose(
                smooth[block], ref.joint_histogram_smooth(*args), **TOL["kernel_vs_reference"]
            )
            expected_d = ref.joint_histogram_smooth_derivative(*args)
            scale = max(np.abs(expected_d).max(), 1e-300)
            assert_allclose(
                dsmooth[block] / scale,
                expected_d / scale,
                **TOL["nid_derivative_vs_reference_scaled"],
            )
        assert count == round(smooth.sum())


def test_grouped_kernels_are_one_parallel_region(rng):
    cam = example_camera("plumb_bob", 64, 48)
    pts, point_bins, groups, image_bins = _grouped(rng, cam, 4, n=300)
    rows = k.grouped_rows(groups, point_bins, 8)
    xyz = np.ascontiguousarray(pts.T)
    padded = k.padded_image_bins(image_bins, 8)
    common = (cam.model_id, cam.params, np.eye(4), xyz, rows)
    assert parallel_regions(k._joint_hist_hard_parallel, *common, padded, 64, 48, 8, 32) == 1
    smooth = (*common, image_bins, 8, 32, k.N_CHUNKS, True, 0, 1.0)
    assert parallel_regions(k._joint_hist_smooth_parallel, *smooth) == 1


@pytest.mark.parametrize("form", ["smooth", "hard"])
def test_grouped_cost_is_the_point_weighted_mean_of_group_nids(form, rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng, n=6000)
    groups = rng.integers(0, 6, len(pts)) * 10 + 3  # any integers
    T = se3_exp(np.array([0.004, -0.003, 0.002, 0.002, -0.001, 0.003]))
    grouped = GroupedNIDCost(cam, image, pts, inten, groups, form=form, parallel=False)
    expected = 0.0
    for g in np.unique(groups):
        sel = groups == g
        one = NIDCost(cam, image, pts[sel], inten[sel], form=form, parallel=False)
        expected += sel.mean() * one.value(T)
    assert grouped.value(T) == pytest.approx(expected, rel=1e-12)
    assert len(grouped) == len(pts) and grouped.n_groups == 6
    if form == "smooth":
        value, grad = grouped.value_and_grad(T)
        parallel = GroupedNIDCost(cam, image, pts, inten, groups, parallel=True)
        v2, g2 = parallel.value_and_grad(T)
        assert (v2, *g2) == (value, *grad)  # bit for bit
        # the gradient against central differences of the value
        h = 1e-6
        numeric = [
            (grouped.value(se3_exp(h * e) @ T) - grouped.value(se3_exp(-h * e) @ T)) / (2 * h)
            for e in np.eye(6)
        ]
        assert_allclose(grad, numeric, rtol=2e-3, atol=2e-6)


def test_each_group_is_the_groups_own_nid(rng):
    """each_group: every group's NID and gradient as its own NIDCost; weighted, the cost."""
    cam = example_camera("pinhole", 200, 150)
    image, pts, inten = textured_scene(cam, rng, n=4000)
    T = se3_exp(np.array([0.01, -0.02, 0.0, 0.003, -0.002, 0.001]))
    groups = rng.integers(0, 5, len(pts)) * 7  # any integers
    grouped = GroupedNIDCost(cam, image, pts, inten, groups, parallel=False)
    values, grads = grouped.each_group(T)
    assert values.shape == (5,) and grads.shape == (5, 6)
    for j, g in enumerate(np.unique(groups)):
        sel = groups == g
        v, gr = NIDCost(cam, image, pts[sel], inten[sel], parallel=False).value_and_grad(T)
        assert values[j] == pytest.approx(v, rel=1e-12)
        assert_allclose(grads[j], gr, rtol=1e-9, atol=1e-12)
    value, grad = grouped.value_and_grad(T)
    assert grouped.weights @ values == pytest.approx(value, rel=1e-12)
    assert_allclose(grouped.weights @ grads, grad, rtol=1e-9, atol=1e-12)
    assert np.array_equal(np.bincount(grouped.group_of_point), np.bincount(groups)[::7])
    with pytest.raises(ValueError, match="smooth"):
        GroupedNIDCost(cam, image, pts, inten, groups, form="hard").each_group(T)


def test_one_group_is_the_plain_nid_bit_for_bit(rng):
    cam = example_camera("fisheye", 200, 150)
    image, pts, inten = textured_scene(cam, rng, n=3000)
    T = se3_exp(np.array([0.01, 0.0, -0.01, 0.002, 0.003, 0.0]))
    one = GroupedNIDCost(cam, image, pts, inten, np.zeros(len(pts), int))
    plain = NIDCost(cam, image, pts, inten)
    assert one.value_and_grad(T)[0] == plain.value_and_grad(T)[0]
    assert np.array_equal(one.value_and_grad(T)[1], plain.value_and_grad(T)[1])


def test_grouped_rows_and_bad_input(rng):
    assert k.grouped_rows([0, 2, 1], quantise([0.1, 0.5, 0.99], 8), 8).tolist() == [0, 20, 15]
    cam = example_camera("pinhole", 32, 24)
    with pytest.raises(ValueError, match="groups"):
        GroupedNIDCost(cam, np.zeros((24, 32)), np.ones((3, 3)), np.ones(3), [0, 1])


def test_median_cut_regions(rng):
    uv = np.column_stack([rng.uniform(0, 1280, 10_000), rng.uniform(0, 480, 10_000)])
    regions = median_cut_regions(uv, 600)
    sizes = np.bincount(regions)
    assert sizes.min() >= 600 and sizes.max() < 1200 and sizes.sum() == 10_000
    # each region is a box: its points' pixel ranges do not overlap another's interior
    assert np.array_equal(regions, median_cut_regions(uv, 600))  # deterministic
    first_cut = regions[uv[:, 0] < np.median(uv[:, 0]) - 1]  # the longer side (u) is cut first
    assert not np.isin(first_cut, regions[uv[:, 0] > np.median(uv[:, 0]) + 1]).any()
    assert np.all(median_cut_regions(uv[:900], 600) == 0)  # fewer than twice: one region
    assert median_cut_regions(np.zeros((0, 2)), 5).shape == (0,)
    with pytest.raises(ValueError, match="region_points"):
        median_cut_regions(uv, 0)


@pytest.mark.parametrize("region_points", [1, 3, 40, 600])
def test_median_cut_kernel_equals_its_reference(rng, region_points):
    """The same regions to the point, ties included: whole pixels repeat, and a row of equal
    u, a block of equal (u, v) and spans of equal length test the tie-breaking."""
    from nbcalib.kernels.regions import median_cut_regions as kernel
    from nbcalib.reference.regions import median_cut_regions as reference

    cases = [
        np.column_stack([rng.uniform(0, 1280, 5000), rng.uniform(0, 960, 5000)]),
        np.floor(np.column_stack([rng.uniform(0, 40, 4000), rng.uniform(0, 30, 4000)])),
        np.column_stack([np.full(300, 7.0), rng.uniform(0, 5, 300)]),
        np.zeros((500, 2)),
        np.array([[0.0, 0.0], [2.0, 2.0], [0.0, 2.0], [2.0, 0.0]] * 60),
    ]
    for uv in cases:
        assert np.array_equal(kernel(uv, region_points), reference(uv, region_points))
        assert np.array_equal(median_cut_regions(uv, region_points), reference(uv, region_points))


def test_median_cut_regions_refuses_non_finite_pixels():
    with pytest.raises(ValueError, match="finite"):
        median_cut_regions(np.array([[0.0, np.nan], [1.0, 2.0]]), 1)


def test_the_cost_setting_chooses_the_term(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng, n=9000)
    pair = RegistrationPair(cam, (image * 255).astype(np.uint8), pts, inten)
    T = np.eye(4)
    config = RefineConfig(hidden_point_removal=False, parallel=False, region_points=1000)
    regional, counts = build_cost([pair], T, config)
    (term,) = regional.costs
    assert isinstance(term, GroupedNIDCost) and 4 <= term.n_groups <= 9
    assert counts == [len(pts)] and len(term) == len(pts)
    plain, _ = build_cost([pair], T, replace(config, cost="nid", orientation_classes=False))
    (one,) = plain.costs
    assert isinstance(one, NIDCost)
    assert set(COSTS) == {"regional", "nid"}
    with pytest.raises(ValueError, match="cost must be one of regional, nid"):
        RefineConfig(cost="mi")
    with pytest.raises(ValueError, match="region_points"):
        RefineConfig(region_points=0)


def test_regional_refine_recovers_a_small_offset(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng, n=20000)
    pair = RegistrationPair(cam, (image * 255).astype(np.uint8), pts, inten)
    config = RefineConfig(
        hidden_point_removal=False, parallel=False, region_points=2500, pyramid_levels=0
    )
    T0 = se3_exp(np.array([0.01, -0.01, 0.0, 0.004, 0.0, -0.004]))
    result = refine([pair], T0, config)
    dt, dr = pose_error(result.T_camera_lidar, np.eye(4))
    assert dt < 0.003 and dr < 0.05
