"""NID cost: kernels vs references, parallel == serial, properties, exact gradients."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.ndimage import gaussian_filter, map_coordinates

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.kernels import nid as k
from nbcalib.reference import nid as ref
from nbcalib.registration.nid import MultiNIDCost, NIDCost, quantise
from nbcalib.transforms import se3_exp
from tests.numba_regions import parallel_regions
from tests.tolerances import TOL


def textured_scene(camera, rng, n=4000, depth=(2.0, 8.0), blur=2.0):
    """An image, and LiDAR points that see it: each point's intensity is a noisy function of the
    image at its true projection (identity extrinsic), so NID is low at the truth."""
    h, w = camera.height, camera.width
    image = gaussian_filter(rng.random((h, w)), blur)
    image = (image - image.min()) / (image.max() - image.min())
    uv = np.column_stack([rng.uniform(1, w - 2, n), rng.uniform(1, h - 2, n)])
    bearings = camera.unproject(uv)
    keep = np.isfinite(bearings[:, 0])
    points = bearings[keep] * rng.uniform(*depth, (keep.sum(), 1))
    truth = map_coordinates(image, [uv[keep, 1], uv[keep, 0]], order=1)
    intensities = np.clip(1.0 - truth + 0.05 * rng.standard_normal(truth.size), 0, 1)
    return image, points, intensities


def nasty_points(camera, rng, n=3000):
    """Points in view plus NaN, behind-camera, border and off-image points."""
    uv = np.column_stack(
        [rng.uniform(-0.5, camera.width - 0.5, n), rng.uniform(-0.5, camera.height - 0.5, n)]
    )
    uv[:20, 0] = -0.5  # exactly on the left/top borders
    uv[20:40, 1] = -0.5
    uv[40:60, 0] = camera.width - 0.5 - 1e-9
    b = camera.unproject(uv)
    pts = b[np.isfinite(b[:, 0])] * rng.uniform(1, 10, (np.isfinite(b[:, 0]).sum(), 1))
    extra = np.array(
        [[np.nan, 0, 1], [0, 0, -5], [0.1, 0.2, -3], [50.0, 0, 1], [0, 0, 0], [np.inf, 1, 1]]
    )
    return np.concatenate([pts, extra])


@pytest.mark.parametrize("model", CAMERA_MODELS)
def test_hard_histogram_matches_reference(model, rng):
    cam = example_camera(model, 160, 120 if model != "equirectangular" else 80)
    # enough points for several blocks per chunk, and a last block that is not full
    pts = nasty_points(cam, rng, n=k.N_CHUNKS * (2 * k.BLOCK + 123))
    point_bins = rng.integers(0, 16, len(pts)).astype(np.uint8)
    image_bins = rng.integers(0, 16, (cam.height, cam.width)).astype(np.uint8)
    T = se3_exp(np.array([0.01, -0.02, 0.03, 0.01, 0.02, -0.01]))
    expected = ref.joint_histogram_hard(cam, T, pts, point_bins, image_bins, 16)
    assert len(pts) > k.N_CHUNKS * 2 * k.BLOCK
    xyz = np.ascontiguousarray(pts.T)
    for parallel in (False, True):
        got = k.joint_hist_hard(
            cam.model_id,
            cam.params,
            T,
            xyz,
            point_bins,
            image_bins,
            16,
            parallel=parallel,
            padded=k.padded_image_bins(image_bins, 16),
        )
        assert np.array_equal(got, expected)


def test_nid_kernels_are_one_parallel_region(rng):
    cam = example_camera("plumb_bob", 64, 48)
    xyz = np.ascontiguousarray(nasty_points(cam, rng, n=200).T)
    point_bins = rng.integers(0, 8, xyz.shape[1]).astype(np.uint8)
    image_bins = rng.integers(0, 8, (48, 64)).astype(np.uint8)
    T = np.eye(4)
    padded = k.padded_image_bins(image_bins, 8)
    common = (cam.model_id, cam.params, T, xyz, point_bins)
    assert parallel_regions(k._joint_hist_hard_parallel, *common, padded, 64, 48, 8, 8) == 1
    smooth = (*common, image_bins, 8, 8, k.N_CHUNKS, True, 0, 1.0)
    assert parallel_regions(k._joint_hist_smooth_parallel, *smooth) == 1


@pytest.mark.parametrize("model", ["plumb_bob", "atan", "omnidir", "equirectangular"])
def test_smooth_histogram_matches_reference(model, rng):
    cam = example_camera(model, 160, 120 if model != "equirectangular" else 80)
    pts = nasty_points(cam, rng, n=800)
    point_bins = rng.integers(0, 8, len(pts)).astype(np.uint8)
    image_bins = rng.integers(0, 8, (cam.height, cam.width)).astype(np.uint8)
    T = se3_exp(np.array([0.01, -0.02, 0.03, 0.01, 0.02, -0.01]))
    expected = ref.joint_histogram_smooth(cam, T, pts, point_bins, image_bins, 8)
    hist, _, count = k._joint_hist_smooth(
        cam.model_id,
        cam.params,
        T,
        pts.T.copy(),
        point_bins,
        image_bins,
        8,
        8,
        k.N_CHUNKS,
        False,
        0,
        1.0,
    )
    assert_allclose(hist, expected, **TOL["kernel_vs_reference"])
    assert_allclose(hist.sum(), count, rtol=1e-12)  # B-spline weights are a partition of unity


def blocky_bins(rng, height, width, bins, block=6):
    """Image bins constant over ``block`` x ``block`` tiles: many 4 x 4 patches fall in one bin."""
    tiles = rng.integers(0, bins, (-(-height // block), -(-width // block))).astype(np.uint8)
    return np.ascontiguousarray(np.kron(tiles, np.ones((block, block), np.uint8))[:height, :width])


@pytest.mark.parametrize("model", ["plumb_bob", "fisheye", "omnidir", "equirectangular"])
@pytest.mark.parametrize("image_kind", ["random", "blocky"])
def test_smooth_derivative_matches_reference(model, image_kind, rng):
    cam = example_camera(model, 160, 120 if model != "equirectangular" else 80)
    pts = nasty_points(cam, rng, n=800)
    point_bins = rng.integers(0, 8, len(pts)).astype(np.uint8)
    if image_kind == "random":
        image_bins = rng.integers(0, 8, (cam.height, cam.width)).astype(np.uint8)
    else:
        image_bins = blocky_bins(rng, cam.height, cam.width, 8)
    T = se3_exp(np.array([0.01, -0.02, 0.03, 0.01, 0.02, -0.01]))
    expected = ref.joint_histogram_smooth(cam, T, pts, point_bins, image_bins, 8)
    expected_d = ref.joint_histogram_smooth_derivative(cam, T, pts, point_bins, image_bins, 8)
    for kernel in (k._joint_hist_smooth, k._joint_hist_smooth_parallel):
        hist, dhist, count = kernel(
            cam.model_id,
            cam.params,
            T,
            pts.T.copy(),
            point_bins,
            image_bins,
            8,
            8,
            k.N_CHUNKS,
            True,
            0,
            1.0,
        )
        assert_allclose(hist, expected, **TOL["kernel_vs_reference"])
        scale = np.abs(expected_d).max()
        assert scale > 0
        assert_allclose(
            dhist / scale, expected_d / scale, **TOL["nid_derivative_vs_reference_scaled"]
        )
        assert count == round(expected.sum())
    if image_kind == "blocky":  # the one-bin shortcut must have been taken for many points
        uv, valid = cam.project(pts @ T[:3, :3].T + T[:3, 3], in_image=True)
        ku, kv = np.floor(uv[valid]).astype(int).T
        one_bin = [
            np.ptp(
                image_bins[np.clip(np.arange(v - 1, v + 3), 0, cam.height - 1)][
                    :, np.clip(np.arange(u - 1, u + 3), 0, cam.width - 1)
                ]
            )
            == 0
            for u, v in zip(ku, kv)
        ]
        assert np.mean(one_bin) > 0.2


def test_parallel_equals_serial_bit_for_bit(rng):
    cam = example_camera("plumb_bob", 320, 240)
    for seed in range(5):
        r = np.random.default_rng(seed)
        image, pts, inten = textured_scene(cam, r, n=3000)
        T = se3_exp(r.normal(0, 0.01, 6))
        costs = [NIDCost(cam, image, pts, inten, parallel=p) for p in (False, True)]
        (v0, g0), (v1, g1) = (c.value_and_grad(T) for c in costs)
        assert v0 == v1 and np.array_equal(g0, g1)
        hard = [NIDCost(cam, image, pts, inten, form="hard", parallel=p) for p in (False, True)]
        assert hard[0].value(T) == hard[1].value(T)


def test_more_threads_than_cores_give_the_same_result(tmp_path):
    """A fixed chunking makes results independent of the thread count."""
    code = (
        "import json, numpy as np\n"
        "from nbcalib.camera import example_camera\n"
        "from nbcalib.registration.nid import NIDCost\n"
        "from tests.test_nid import textured_scene\n"
        "cam = example_camera('plumb_bob', 320, 240)\n"
        "img, pts, inten = textured_scene(cam, np.random.default_rng(3), n=3000)\n"
        "v, g = NIDCost(cam, img, pts, inten).value_and_grad(np.eye(4))\n"
        "print(json.dumps([v, *g.tolist()]))\n"
    )
    outs = []
    for threads in ("1", "7"):
        env = {**__import__("os").environ, "NUMBA_NUM_THREADS": threads}
        run = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
        )
        outs.append(json.loads(run.stdout))
    assert outs[0] == outs[1]


def test_nid_properties(rng):
    bins = 16
    a = rng.integers(0, bins, 5000)
    same = np.zeros((bins, bins))
    np.add.at(same, (a, a), 1)
    assert ref.nid_from_histogram(same) == pytest.approx(0.0, abs=1e-12)
    value, _ = k._nid_from_hist(same, np.zeros((bins, bins, 6)), False)
    assert value == pytest.approx(0.0, abs=1e-12)
    independent = np.outer(np.full(bins, 1.0), np.full(bins, 1.0))  # p(a, b) = p(a) p(b)
    assert k._nid_from_hist(independent, np.zeros((bins, bins, 6)), False)[0] == pytest.approx(1.0)
    # relabelling bins changes nothing
    random_hist = rng.random((bins, bins))
    perm_rows, perm_cols = rng.permutation(bins), rng.permutation(bins)
    v1 = k._nid_from_hist(random_hist, np.zeros((bins, bins, 6)), False)[0]
    v2 = k._nid_from_hist(random_hist[perm_rows][:, perm_cols], np.zeros((bins, bins, 6)), False)[0]
    assert_allclose(v1, v2, rtol=1e-12)
    assert_allclose(v1, ref.nid_from_histogram(random_hist), rtol=1e-12)
    assert 0.0 <= v1 <= 1.0
    # empty histogram and a single occupied cell: no information
    assert k._nid_from_hist(np.zeros((bins, bins)), np.zeros((bins, bins, 6)), False)[0] == 1.0


def test_nid_is_lowest_at_the_truth_and_order_invariant(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng)
    for form in ("hard", "smooth"):
        cost = NIDCost(cam, image, pts, inten, form=form)
        at_truth = cost.value(np.eye(4))
        for delta in np.eye(6) * 0.02:
            assert cost.value(se3_exp(delta)) > at_truth
        order = rng.permutation(len(pts))
        shuffled = NIDCost(cam, image, pts[order], inten[order], form=form)
        assert_allclose(shuffled.value(np.eye(4)), at_truth, rtol=1e-12)


@pytest.mark.parametrize("model", CAMERA_MODELS)
def test_gradient_matches_finite_differences(model, rng):
    cam = example_camera(model, 320, 240 if model != "equirectangular" else 160)
    image, pts, inten = textured_scene(cam, rng, n=3000)
    # keep points away from the image border, where entering/leaving points make jumps
    uv, _ = cam.project(pts)
    inner = (
        (uv[:, 0] > 8) & (uv[:, 0] < cam.width - 9) & (uv[:, 1] > 8) & (uv[:, 1] < cam.height - 9)
    )
    cost = NIDCost(cam, image, pts[inner], inten[inner])
    T = se3_exp(np.array([0.002, -0.003, 0.001, 0.001, -0.0015, 0.0005]))
    value, grad = cost.value_and_grad(T)
    h = 1e-6
    numeric = np.array(
        [
            (cost.value(se3_exp(h * e) @ T) - cost.value(se3_exp(-h * e) @ T)) / (2 * h)
            for e in np.eye(6)
        ]
    )
    assert value == cost.value(T)
    assert_allclose(grad, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


def test_multi_pair_cost_is_the_sum(rng):
    cam = example_camera("pinhole", 320, 240)
    pairs = [textured_scene(cam, np.random.default_rng(s)) for s in range(3)]
    costs = [NIDCost(cam, *p) for p in pairs]
    multi = MultiNIDCost(costs)
    T = se3_exp(np.array([0.01, 0, 0, 0, 0.01, 0]))
    v, g = multi.value_and_grad(T)
    assert_allclose(v, sum(c.value(T) for c in costs), rtol=1e-12)
    assert_allclose(g, sum(c.value_and_grad(T)[1] for c in costs), rtol=1e-12)


def test_quantise_rule():
    assert quantise(np.array([0.0, 0.0624, 0.0625, 0.999, 1.0, 1.5, -1, np.nan]), 16).tolist() == [
        0,
        0,
        1,
        15,
        15,
        15,
        0,
        0,
    ]


def test_numpy_baseline_matches_kernel(rng):
    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng)
    cost = NIDCost(cam, image, pts, inten, form="hard")
    T = se3_exp(np.array([0.01, 0, 0.02, 0.01, 0, 0]))
    baseline = ref.nid_hard_numpy(
        cam.model,
        cam.intrinsics,
        cam.distortion_coeffs,
        T,
        cost.points,
        cost.point_bins,
        cost.image_bins,
        16,
    )
    assert_allclose(cost.value(T), baseline, rtol=1e-12)


def test_bad_input(rng):
    cam = example_camera("pinhole", 64, 48)
    img = rng.random((48, 64))
    pts = rng.random((10, 3))
    with pytest.raises(ValueError, match="form"):
        NIDCost(cam, img, pts, pts[:, 0], form="soft")
    with pytest.raises(ValueError, match="64 x 48"):
        NIDCost(cam, img[:40], pts, pts[:, 0])
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        NIDCost(cam, img, pts[:, :2], pts[:, 0])
    with pytest.raises(ValueError, match="9 intensities for 10"):
        NIDCost(cam, img, pts, pts[:9, 0])
    with pytest.raises(ValueError, match="no gradient"):
        NIDCost(cam, img, pts, pts[:, 0], form="hard").value_and_grad(np.eye(4))
    with pytest.raises(ValueError, match="4 x 4"):
        NIDCost(cam, img, pts, pts[:, 0]).value(np.eye(3))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        NIDCost(cam, img * 2, pts, pts[:, 0])


def test_visible_indices_are_the_visible_points_in_pixel_order(rng):
    """The cache-friendly order of hidden-point removal changes no NID beyond rounding."""
    from nbcalib.preprocess.lidar_image import visible_indices, visible_mask

    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng, n=3000)
    pts = np.concatenate([pts, pts[:500] * 1.5, [[np.nan, 0, 1], [0, 0, -2]]])  # occluded, bad
    inten = np.concatenate([inten, inten[:500], [0.5, 0.5]])
    T = se3_exp(np.array([0.002, -0.003, 0.001, 0.001, -0.0015, 0.0005]))
    mask = visible_mask(cam, T, pts, window=1)
    idx = visible_indices(cam, T, pts, window=1)
    assert 0 < idx.size < len(pts)
    assert np.array_equal(np.sort(idx), np.flatnonzero(mask))
    uv, _ = cam.project(pts[idx] @ T[:3, :3].T + T[:3, 3])
    pixel = np.floor(uv[:, 1] + 0.5) * cam.width + np.floor(uv[:, 0] + 0.5)
    assert np.all(np.diff(pixel) >= 0)
    keep = np.flatnonzero(mask)
    for form in ("hard", "smooth"):
        a = NIDCost(cam, image, pts[keep], inten[keep], form=form)
        b = NIDCost(cam, image, pts[idx], inten[idx], form=form)
        assert_allclose(b.value(T), a.value(T), rtol=1e-12)


def test_a_pair_computes_its_visible_set_once_per_pose(rng, monkeypatch):
    """RegistrationPair.visibility keeps the last two poses' z-buffers; the subsets it gives are
    visible_indices' to the index, with or without a selection."""
    import nbcalib.preprocess.lidar_image as li
    from nbcalib.registration.config import RefineConfig
    from nbcalib.registration.refine import RegistrationPair, visible_subset

    cam = example_camera("plumb_bob", 320, 240)
    image, pts, inten = textured_scene(cam, rng, n=3000)
    pair = RegistrationPair(cam, image, pts, inten)
    config = RefineConfig(window=1)
    poses = [
        se3_exp(np.array([0.002 * k, -0.003, 0.001, 0.001 * k, -0.0015, 0.0005])) for k in range(3)
    ]
    calls = []
    real = li.visibility
    monkeypatch.setattr(li, "visibility", lambda *a, **k: calls.append(1) or real(*a, **k))
    half = lambda keep: keep[::2]  # noqa: E731
    for T in (poses[0], poses[1], poses[0], poses[1]):  # two poses: one z-buffer each
        want = li.visible_indices(cam, T, pts, margin=config.depth_margin, window=1)
        assert np.array_equal(visible_subset(pair, T, config), want)
        want_half = li.visible_indices(
            cam, T, pts, margin=config.depth_margin, window=1, select=half
        )
        assert np.array_equal(visible_subset(pair, T, config, select=half), want_half)
    assert len(calls) == 2 + 8  # 2 by the pair; 8 by visible_indices, the reference here
    visible_subset(pair, poses[2], config)  # a third pose pushes out the oldest
    visible_subset(pair, poses[0], config)
    assert len(calls) == 10 + 2
    pair.camera = example_camera("plumb_bob", 320, 240)  # another camera: computed again
    visible_subset(pair, poses[0], config)
    assert len(calls) == 13
