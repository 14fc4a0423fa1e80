"""Camera-shaped LiDAR views (nbcalib.matching.views) and multi-view matching (multiview)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from tolerances import TOL

from nbcalib.camera import create_camera, example_camera
from nbcalib.initial_guess import estimate_initial_guess
from nbcalib.matching import Correspondences, correspondences_from_matches, match_views
from nbcalib.matching.views import (
    _fill_index,
    heading_rotations,
    prior_rotations,
    render_view,
    scaled_camera,
    view_scale,
)
from nbcalib.metrics import pose_errors
from nbcalib.synthetic import default_T_camera_lidar
from nbcalib.transforms import make_T, transform_points

R_FORWARD = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


def test_headings_are_level_rotations_at_even_yaws():
    rotations = heading_rotations(8, offset_deg=10.0)
    assert len(rotations) == 8
    for k, R in enumerate(rotations):
        np.testing.assert_allclose(R @ R.T, np.eye(3), **TOL["transform"])
        assert np.linalg.det(R) == pytest.approx(1.0)
        axis = R[2]  # optical axis in LiDAR coordinates
        assert axis[2] == pytest.approx(0.0, abs=1e-12)  # level
        assert R[1] == pytest.approx([0.0, 0.0, -1.0])  # image down = LiDAR down
        yaw = math.degrees(math.atan2(axis[1], axis[0]))
        assert (yaw - (10.0 + 45.0 * k) + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_allclose(heading_rotations(1)[0], R_FORWARD, atol=1e-15)
    with pytest.raises(ValueError, match="n_headings"):
        heading_rotations(0)


def test_prior_rotations_turn_about_lidar_z():
    truth = default_T_camera_lidar("spinning", 3)[:3, :3]
    R0, R1 = prior_rotations(truth, (0.0, 30.0))
    np.testing.assert_allclose(R0, truth, atol=1e-15)
    # a LiDAR direction at yaw +30 deg from d shows in view 1 where d shows in view 0
    d = np.array([0.3, -0.8, 0.1])
    turn = np.array(
        [
            [math.cos(0.5236), -math.sin(0.5236), 0],
            [math.sin(0.5236), math.cos(0.5236), 0],
            [0, 0, 1],
        ]
    )
    np.testing.assert_allclose(R1 @ (turn @ d), R0 @ d, atol=1e-4)


@pytest.mark.parametrize("model", ["pinhole", "plumb_bob", "fisheye", "omnidir", "equirectangular"])
def test_scaled_camera_scales_pixels_about_the_image_corner(model, rng):
    camera = example_camera(model)
    small = scaled_camera(camera, 0.25)
    assert (small.width, small.height) == (round(camera.width / 4), round(camera.height / 4))
    p = rng.normal(size=(50, 3)) + np.array([0.0, 0.0, 4.0])
    uv, ok = camera.project(p)
    uv_s, ok_s = small.project(p)
    assert np.array_equal(ok, ok_s) and ok.sum() > 10
    # pixel centres at integers: u' = (u + 0.5) s - 0.5
    np.testing.assert_allclose(uv_s[ok], (uv[ok] + 0.5) * 0.25 - 0.5, **TOL["transform"])
    with pytest.raises(ValueError, match="scale"):
        scaled_camera(camera, 0.0)


def test_view_scale_gives_the_asked_resolution():
    camera = example_camera("pinhole")  # about 0.06 degree per pixel at the centre
    s = view_scale(camera, 5.0)
    from nbcalib.matching.match import pixels_per_radian

    assert pixels_per_radian(scaled_camera(camera, s)) * math.pi / 180 == pytest.approx(
        5.0, rel=2e-2
    )
    assert view_scale(camera, 1e6) == 1.0  # never above the camera's own resolution


def test_fill_index_takes_existing_rows_within_the_radius():
    index = np.full((9, 9), -1, dtype=np.int32)
    index[4, 4] = 7
    filled = _fill_index(index, 2)
    assert set(np.unique(filled)) == {-1, 7}
    rows, cols = np.nonzero(filled == 7)
    assert np.max(np.maximum(abs(rows - 4), abs(cols - 4))) == 2  # Chebyshev radius 2
    assert np.count_nonzero(filled == 7) == 25
    assert np.array_equal(_fill_index(index, 0), index)


def _cylinder(rng, n=250_000, radius=8.0, half=np.pi):
    """A textured cylinder wall around the LiDAR: intensities from blurred noise on (phi, z).

    ``half``: the wall's half-angle about LiDAR +x (pi: all around).
    """
    import cv2

    phi = rng.uniform(-half, half, n)
    z = rng.uniform(-3.0, 3.0, n)
    points = np.column_stack([radius * np.cos(phi), radius * np.sin(phi), z])
    # texture cells of ~4 cm, blobs of ~0.3 m: corners for the keypoint detectors
    texture = cv2.GaussianBlur(rng.uniform(0.0, 1.0, (150, 1256)).astype(np.float32), (0, 0), 4.0)
    texture = (texture - texture.min()) / (texture.max() - texture.min())
    rows = np.minimum(((z + 3.0) / 6.0 * 150).astype(np.int64), 149)
    cols = np.minimum(((phi + np.pi) / (2 * np.pi) * 1256).astype(np.int64), 1255)
    return points, texture[rows, cols].astype(np.float64)


def test_render_view_index_lifts_to_the_points_shown(rng):
    points, intensities = _cylinder(rng, n=60_000)
    camera = example_camera("plumb_bob", 640, 480)
    R = heading_rotations(4)[1]  # looking along LiDAR +y
    view = render_view(camera, R, points, intensities, scale=0.5, fill_radius=1)
    assert view.intensity.shape == (240, 320) and view.heading_deg == pytest.approx(90.0)
    own = view.index >= 0
    shown = view.intensity > 0
    assert 0.3 < view.fill_fraction <= 1.0 and shown.sum() > own.sum()
    assert np.all(shown[own])  # the fill only adds
    # every z-buffer pixel holds a point that projects into it
    v, u = np.nonzero(own)
    uv, ok = view.camera.project(transform_points(view.T_vcam_lidar, points[view.index[v, u]]))
    assert ok.all()
    assert np.max(np.abs(uv - np.column_stack([u, v]))) <= 0.5 + 1e-9


def test_render_view_splat_fills_holes_with_nearer_points_first(rng):
    points, intensities = _cylinder(rng, n=20_000, radius=3.0)
    camera = example_camera("pinhole", 640, 480)
    R = heading_rotations(1)[0]
    bare = render_view(camera, R, points, intensities, scale=0.5, fill_radius=0)
    splat = render_view(
        camera, R, points, intensities, scale=0.5, fill_radius=0, splat_pixels_at_1m=6.0
    )
    assert np.count_nonzero(splat.index >= 0) > np.count_nonzero(bare.index >= 0)
    # the splat only adds: the z-buffer's own pixels keep their points
    own = bare.index >= 0
    assert np.array_equal(splat.index[own], bare.index[own])


def _self_consistent_pair(rng, yaw_deg):
    """A cloud and a camera image rendered from the same cloud (no modality gap)."""
    points, intensities = _cylinder(rng)
    camera = create_camera("pinhole", [400.0, 400.0, 319.5, 239.5], [], 640, 480)
    R_lidar_camera = make_T(heading_rotations(1, offset_deg=yaw_deg)[0].T, [0.05, -0.1, 0.02])
    T_camera_lidar = np.linalg.inv(R_lidar_camera)
    image = render_view(
        camera,
        T_camera_lidar[:3, :3],
        points,
        intensities,
        scale=1.0,
        fill_radius=3,
        t_vcam_lidar=T_camera_lidar[:3, 3],
    ).intensity
    return camera, image, points, intensities, T_camera_lidar


@pytest.mark.parametrize("yaw_deg", [-100.0])
def test_match_views_finds_the_heading_and_the_pose_with_sift(rng, yaw_deg):
    camera, image, points, intensities, truth = _self_consistent_pair(rng, yaw_deg)
    mv = match_views(
        camera,
        image,
        points,
        intensities,
        matcher="sift",
        views=8,
        camera_normalization="none",
        lidar_normalization="none",
        name="p",
        max_keypoints=1500,
        fine_max_keypoints=3000,
    )
    # 8 headings, then one view from the pose they give (refine_view=True)
    assert len(mv.views) == 9 and 0 <= mv.best < 8 and mv.pooled[-1] == 8
    # the sweep at max_keypoints, the refined view at fine_max_keypoints
    assert [v.matches.info["max_keypoints"] for v in mv.views] == [1500] * 8 + [3000]
    best = mv.views[mv.best].view.heading_deg
    assert abs((best - yaw_deg + 180.0) % 360.0 - 180.0) <= 22.5 + 1e-9
    refined = mv.views[8].view.heading_deg
    assert abs((refined - yaw_deg + 180.0) % 360.0 - 180.0) < 1.0
    corr = mv.correspondences
    assert len(corr) >= 20 and corr.names == ("p",)
    # the matches' own test (a tiny SIFT scene bounds the pose to ~0.14 deg, which the default
    # precision test for learned matches' shared error refuses: tests/test_initial_guess.py)
    guess = estimate_initial_guess(
        camera, corr.uv_camera, corr.points_lidar, weights=corr.weights, precision_scale=0.0
    )
    e = pose_errors(guess.T_camera_lidar, truth)
    assert guess.success
    assert e["rotation_error_deg"] < TOL["multiview_self_consistent_deg"]["atol"]
    assert e["translation_error_m"] < TOL["multiview_self_consistent_m"]["atol"]
    assert "<- best" in mv.summary()


def test_match_views_with_a_prior_renders_only_around_it(rng):
    camera, image, points, intensities, truth = _self_consistent_pair(rng, 150.0)
    mv = match_views(
        camera,
        image,
        points,
        intensities,
        matcher="sift",
        T_camera_lidar_prior=truth,
        prior_yaw_offsets_deg=(0.0, 20.0),
        refine_view=False,
        camera_normalization="none",
        lidar_normalization="none",
    )
    assert len(mv.views) == 2 and mv.best == 0
    assert mv.views[0].ransac_inliers > mv.views[1].ransac_inliers


def test_reference_matches_put_lidar_keypoints_where_the_index_map_shows_the_point(rng):
    """matches.json for the reference toolbox: it truncates kpts1 to a pixel and reads the index
    map there, so each LiDAR keypoint must be the (integer) pixel that shows its point."""
    from nbcalib.matching.find import reference_matches
    from nbcalib.preprocess.lidar_image import make_virtual_camera, render_lidar_image

    camera, image, points, intensities, _ = _self_consistent_pair(rng, 20.0)
    mv = match_views(
        camera,
        image,
        points,
        intensities,
        matcher="sift",
        views=6,
        refine_view=False,
        camera_normalization="none",
        lidar_normalization="none",
    )
    vcam, T_vcam_lidar = make_virtual_camera(math.pi)
    index = render_lidar_image(vcam, T_vcam_lidar, points, intensities).index
    corr = mv.correspondences
    m = reference_matches(corr, index, matcher="sift")
    shown = np.isin(corr.point_index, index[index >= 0])
    assert 0 < m.num_matches == int(np.count_nonzero(shown)) <= len(corr)
    u, v = m.kpts_lidar.astype(np.int64).T
    np.testing.assert_array_equal(m.kpts_lidar, np.column_stack([u, v]))  # whole pixels
    np.testing.assert_array_equal(index[v, u], corr.point_index[shown])
    np.testing.assert_array_equal(m.kpts_camera, corr.uv_camera[shown])
    # lifting the file's keypoints (no search radius) finds exactly those points again
    lifted = correspondences_from_matches(m, index, points, search_radius=0.0)
    np.testing.assert_array_equal(lifted.point_index, corr.point_index[shown])


def test_match_views_checks_its_inputs(rng):
    camera = example_camera("pinhole", 64, 48)
    with pytest.raises(ValueError, match="camera_image"):
        match_views(camera, np.zeros((10, 10), np.uint8), np.zeros((5, 3)), np.zeros(5))
    with pytest.raises(ValueError, match="intensities"):
        match_views(camera, np.zeros((48, 64), np.uint8), np.zeros((5, 3)), np.zeros(4))
    # an empty cloud: no view is matched, no correspondences, no error
    mv = match_views(
        camera, np.zeros((48, 64), np.uint8), np.zeros((0, 3)), np.zeros(0), matcher="sift"
    )
    assert mv.best == -1 and isinstance(mv.correspondences, Correspondences)
    assert len(mv.correspondences) == 0


def test_find_matches_views_then_initial_guess_on_a_work_directory(tmp_path, monkeypatch):
    """The CLI end to end: views are the default of find-matches; initial-guess reads them."""
    from nbcalib.cli import main
    from nbcalib.io.calib_json import AUTO_STAGE
    from nbcalib.matching.matches import read_matches_json
    from nbcalib.preprocess.lidar_image import make_virtual_camera
    from nbcalib.preprocess.prepare import render_pairs
    from nbcalib.products import PairData, VirtualCamera
    from nbcalib.workdir import WorkDir, make_calib, set_virtual_camera

    rng = np.random.default_rng(3)
    camera, image, points, intensities, truth = _self_consistent_pair(rng, 60.0)
    # the work directory stores float32 values: use them from the start
    points = points.astype(np.float32).astype(np.float64)
    intensities = intensities.astype(np.float32).astype(np.float64)
    vcam, T_vcam_lidar = make_virtual_camera(math.pi, equirectangular_size=(720, 360))
    virtual, (pair,) = render_pairs(
        [PairData("000000", image, points, intensities)], VirtualCamera(vcam, T_vcam_lidar)
    )
    wd = WorkDir(tmp_path / "work")
    wd.prepare()
    wd.write_pair(pair)
    calib = make_calib(camera, ["000000"])
    set_virtual_camera(calib, virtual)
    wd.write_calib(calib)
    monkeypatch.setenv("NBCALIB_MODEL_DIR", str(tmp_path / "no-models"))
    args = ["--camera-normalization", "none", "--lidar-normalization", "none"]
    assert (
        main(["-q", "find-matches", str(wd.path), "--matcher", "sift", "--views", "6", *args]) == 0
    )
    m = read_matches_json(wd.matches_path("000000"))
    assert m.info["mode"] == "views" and len(m.info["views"]) == 7  # 6 headings + refined
    corr = wd.read_correspondences(wd.load_pair("000000"), search_radius=0.0)
    assert len(corr) >= 20 and m.num_matches <= len(corr)
    assert (wd.path / "000000_matches.png").is_file()
    assert main(["-q", "initial-guess", str(wd.path), "--precision-scale", "0"]) == 0
    e = pose_errors(wd.read_calib().get_T_camera_lidar(AUTO_STAGE), truth)
    assert e["rotation_error_deg"] < TOL["multiview_self_consistent_deg"]["atol"]
    assert e["translation_error_m"] < TOL["multiview_self_consistent_m"]["atol"]


def test_inpaint_coverage_fills_the_gaps_between_rings_and_nothing_outside():
    from nbcalib.matching.views import inpaint_coverage

    image = np.zeros((60, 80), np.uint8)
    image[20:50:4, 10:70] = 200  # rings every 4 rows: gaps of 3 rows between them
    image[22, 30] = 0  # and a hole in a ring
    out = inpaint_coverage(image, 5)
    inside = np.zeros_like(image, bool)
    inside[20:49, 10:70] = True  # first ring (row 20) to last (row 48)
    assert np.all(out[inside] >= 1), "every gap of the coverage is filled"
    assert np.all(out[inside] > 100), "with values of the rings around it"
    assert np.all(out[:20] == 0) and np.all(out[49:] == 0), "no sky, no ground below"
    assert np.all(out[:, :10] == 0) and np.all(out[:, 70:] == 0)
    assert np.array_equal(out[image > 0], image[image > 0]), "shown pixels unchanged"
    # a gap wider than the width stays empty
    wide = np.zeros((40, 40), np.uint8)
    wide[10, :] = wide[30, :] = 90
    assert np.all(inpaint_coverage(wide, 5)[15:26] == 0)
    with pytest.raises(ValueError, match="width"):
        inpaint_coverage(image, 0)


def test_render_view_inpaint_keeps_the_index_map_unfilled(rng):
    points, intensities = _cylinder(rng, n=20_000)
    camera = example_camera("plumb_bob", 640, 480)
    R = heading_rotations(4)[1]
    plain = render_view(camera, R, points, intensities, scale=0.5, fill_radius=1)
    painted = render_view(camera, R, points, intensities, scale=0.5, fill_radius=1, inpaint=9)
    assert painted.fill_fraction > plain.fill_fraction
    np.testing.assert_array_equal(painted.index, plain.index)
    shown = plain.intensity > 0
    np.testing.assert_array_equal(painted.intensity[shown], plain.intensity[shown])


def test_find_correspondences_retries_finer_inpainted_views_until_a_guess_passes(monkeypatch, rng):
    """The first attempt's matches are wrong, the second's right: the second is kept, and the
    attempts are recorded; no retries without retry_pixels_per_degree."""
    from nbcalib.matching import find as find_module
    from nbcalib.matching import multiview
    from nbcalib.matching.config import MatchConfig
    from nbcalib.products import PairData

    camera = example_camera("pinhole", 640, 480)
    truth = default_T_camera_lidar("spinning", 1)
    uv = rng.uniform([0, 0], [639, 479], (200, 2))
    depth = rng.uniform(3, 30, len(uv))
    points = transform_points(np.linalg.inv(truth), camera.unproject(uv) * depth[:, None])
    good = Correspondences(uv, points, uv, np.arange(200), np.zeros(200, int), ("p",), 200)
    bad_uv = rng.uniform([0, 0], [639, 479], (200, 2))
    bad = Correspondences(bad_uv, points, bad_uv, np.arange(200), np.zeros(200, int), ("p",), 200)
    seen = []

    def fake_match_views(camera, image, pts, values, cfg, **kwargs):
        seen.append((cfg.pixels_per_degree, cfg.inpaint_deg, cfg.max_keypoints))
        corr = bad if len(seen) == 1 else good
        return multiview.MultiViewMatches([], -1, (), corr, 0.0)

    monkeypatch.setattr(multiview, "match_views", fake_match_views)
    from nbcalib.preprocess.lidar_image import LidarImage

    index = np.full((10, 20), -1, np.int32)
    lidar = LidarImage(np.zeros((10, 20), np.uint8), index, None)
    pair = PairData("p", np.zeros((480, 640), np.uint8), points, np.zeros(200), lidar)
    cfg = MatchConfig(
        matcher="sift",
        retry_pixels_per_degree=(10.0, 15.0),
        retry_inpaint_deg=2.0,
        max_keypoints=1024,
    )
    found = find_module.find_correspondences(camera, pair, cfg)
    # the sweep with max_keypoints, the retries with fine_max_keypoints
    assert seen == [(None, 0.0, 1024), (10.0, 2.0, 2048)], "stops at the first attempt that passes"
    assert found.kept_attempt == 1 and found.correspondences is good
    assert [a["guess_ok"] for a in found.attempts] == [False, True]
    seen.clear()
    found = find_module.find_correspondences(
        camera, pair, MatchConfig(matcher="sift", retry_pixels_per_degree=(), max_keypoints=1024)
    )
    assert seen == [(None, 0.0, 1024)] and found.kept_attempt == 0
    with pytest.raises(ValueError, match="fine_max_keypoints"):
        MatchConfig(fine_max_keypoints=0)


def test_mutual_nearest_equals_a_loop_over_keypoints(rng):
    from nbcalib.matching.match import mutual_nearest

    d0 = rng.standard_normal((40, 8)).astype(np.float32)
    d1 = np.concatenate(
        [d0[:25] + 0.05 * rng.standard_normal((25, 8)), rng.standard_normal((30, 8))]
    )
    d0 /= np.linalg.norm(d0, axis=1, keepdims=True)
    d1 = (d1 / np.linalg.norm(d1, axis=1, keepdims=True)).astype(np.float32)
    matches, scores = mutual_nearest(d0, d1)
    for i in range(len(d0)):  # the slow definition
        j = int(np.argmax([float(d0[i] @ d1[k]) for k in range(len(d1))]))
        back = int(np.argmax([float(d0[k] @ d1[j]) for k in range(len(d0))]))
        assert matches[i] == (j if back == i else -1)
        assert scores[i] == pytest.approx(float(d0[i] @ d1[j]) if back == i else 0.0, abs=1e-6)
    assert np.all(matches[:25] == np.arange(25))  # the perturbed copies find their originals
    empty, none = mutual_nearest(d0[:0], d1)
    assert empty.shape == (0,) and none.shape == (0,)


def test_match_images_reuses_the_camera_features_it_caches(rng):
    from nbcalib.matching import match_images

    camera, image, points, intensities, truth = _self_consistent_pair(rng, 30.0)
    view = render_view(camera, truth[:3, :3], points, intensities, scale=1.0, fill_radius=2)
    cache: dict = {}
    plain = match_images(image, view.intensity, matcher="xfeat-lighterglue", max_keypoints=512)
    first = match_images(
        image, view.intensity, matcher="xfeat-lighterglue", max_keypoints=512, cache=cache
    )
    again = match_images(
        image, view.intensity, matcher="xfeat-lighterglue", max_keypoints=512, cache=cache
    )
    assert len(cache) == 1
    for m in (first, again):
        assert np.array_equal(m.kpts_camera, plain.kpts_camera)
        assert np.array_equal(m.matches, plain.matches)
    screened = match_images(
        image, view.intensity, matcher="xfeat-lighterglue", max_keypoints=512, screen=True
    )
    assert screened.info["screen"] and not plain.info["screen"]
    assert screened.num_matches > 0 and np.all(screened.confidence <= 1.0 + 1e-6)


def test_the_screen_runs_the_matcher_on_the_views_it_ranks_first(rng):
    """12 headings screened, the learned matcher on 3: the best and pooled views are among
    them, the same best as the matcher on every view, every view drawn once."""
    camera, image, points, intensities, _ = _self_consistent_pair(rng, 60.0)
    kwargs = dict(matcher="xfeat-lighterglue", views=12, max_keypoints=512, refine_view=False)
    done = []
    mv = match_views(
        camera, image, points, intensities, screen_views=3, progress=lambda k, n: done.append(n),
        **kwargs,
    )  # fmt: skip
    every = match_views(camera, image, points, intensities, screen_views=0, **kwargs)
    screened = [v.screened for v in mv.views]
    assert sum(not s for s in screened) == 3 and not any(v.screened for v in every.views)
    assert not screened[mv.best] and all(not screened[k] for k in mv.pooled)
    assert mv.views[mv.best].view.heading_deg == every.views[every.best].view.heading_deg
    assert mv.views[mv.best].ransac_inliers == every.views[every.best].ransac_inliers
    assert len(done) == 12 + 3 and set(done) == {15}
    assert "(screened out)" in mv.summary()


def test_the_screen_also_sends_the_views_that_agree_to_the_matcher():
    """Views whose screened rotation agrees with the first's (the pool's rule) are matched in
    full beyond screen_views; disagreeing or weak ones are not."""
    from types import SimpleNamespace

    from nbcalib.matching.config import MatchConfig
    from nbcalib.matching.multiview import _screened_choice
    from nbcalib.transforms import so3_exp

    def view(support, angle_deg):
        R = None if angle_deg is None else so3_exp([0.0, 0.0, math.radians(angle_deg)])
        return SimpleNamespace(ransac_inliers=support, R_camera_lidar=R)

    results = [view(50, 0.0), view(40, 30.0), view(30, 1.0), view(20, 0.5), view(5, 0.2)]
    results += [view(12, None), view(25, 60.0)]
    cfg = MatchConfig(screen_views=2)
    # the two best, then 2 and 3 (agree, >= min_pool_support); 4 too weak, 5 no rotation
    assert _screened_choice(results, cfg) == {0, 1, 2, 3}
    assert _screened_choice(results, MatchConfig(screen_views=2, pool=False)) == {0, 1}
    assert _screened_choice([], cfg) == set()
    # matched_views caps them, the screen's best supported first (2 before 3)
    assert _screened_choice(results, MatchConfig(screen_views=2, matched_views=3)) == {0, 1, 2}
    assert _screened_choice(results, MatchConfig(screen_views=2, matched_views=9)) == {0, 1, 2, 3}
    assert _screened_choice(results, MatchConfig(screen_views=4, matched_views=1)) == {0}
    with pytest.raises(ValueError, match="matched_views"):
        MatchConfig(matched_views=-1)
