"""Keypoint matching without torch: file format, rotations, SIFT fallback, normalisations, CLI."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from tolerances import TOL

from nbcalib.errors import InputError
from nbcalib.matching import (
    Matches,
    available_matchers,
    draw_matches,
    fill_holes,
    match_images,
    normalize_image,
    read_matches_json,
    rotate_image,
    unrotate_points,
    write_matches_json,
)
from nbcalib.matching.onnx_matcher import filter_matches
from nbcalib.matching.sift import sift_features, sift_match


def textured_image(rng, height=360, width=480) -> np.ndarray:
    """Blobs and edges at several scales: something SIFT finds many distinct keypoints on."""
    import cv2

    image = np.zeros((height, width), np.float32)
    for cell in (40, 12, 4):
        noise = rng.random((height // cell + 2, width // cell + 2)).astype(np.float32)
        image += cv2.resize(noise, (width, height), interpolation=cv2.INTER_CUBIC)
    for _ in range(25):
        x0, y0 = rng.integers(0, width - 40), rng.integers(0, height - 40)
        w, h = rng.integers(10, 60), rng.integers(10, 60)
        image[y0 : y0 + h, x0 : x0 + w] += rng.uniform(-1.5, 1.5)
    image -= image.min()
    return (255 * image / image.max()).astype(np.uint8)


@pytest.fixture
def warped_pair(rng):
    """An image, a homography-warped copy of it and the homography (copy = H @ image)."""
    import cv2

    image = textured_image(rng)
    H = np.array([[0.92, 0.06, 18.0], [-0.04, 0.95, 12.0], [2e-5, -1e-5, 1.0]])
    warped = cv2.warpPerspective(image, H, (image.shape[1], image.shape[0]))
    return image, warped, H


def correct_fraction(matches: Matches, H: np.ndarray, tol_px: float = 2.0):
    import cv2

    uv0, uv1, _ = matches.matched()
    predicted = cv2.perspectiveTransform(uv0[None], H)[0]
    correct = np.linalg.norm(predicted - uv1, axis=1) < tol_px
    return int(correct.sum()), float(correct.mean()) if len(correct) else 0.0


# -------------------------------------------------------------------- matches.json


def make_matches(rng, m=7, k=5) -> Matches:
    matches = rng.integers(-1, k, size=m)
    return Matches(
        rng.uniform(0, 500, (m, 2)),
        rng.uniform(0, 500, (k, 2)),
        matches,
        rng.random(m),
        matcher="sift",
        info={"rotate_camera": 90},
    )


def test_matches_json_round_trip(tmp_path, rng):
    original = make_matches(rng)
    path = tmp_path / "000000_matches.json"
    write_matches_json(path, original)
    doc = json.loads(path.read_text())
    # the reference's layout: flat keypoint lists, one match and one confidence per kpts0
    assert len(doc["kpts0"]) == 2 * len(original.kpts_camera)
    assert len(doc["kpts1"]) == 2 * len(original.kpts_lidar)
    assert doc["matches"] == [int(x) for x in original.matches]
    back = read_matches_json(path)
    np.testing.assert_array_equal(back.kpts_camera, original.kpts_camera)
    np.testing.assert_array_equal(back.kpts_lidar, original.kpts_lidar)
    np.testing.assert_array_equal(back.matches, original.matches)
    np.testing.assert_array_equal(back.confidence, original.confidence)
    assert back.matcher == "sift" and back.info == {"rotate_camera": 90}


def test_reads_the_reference_scripts_output(tmp_path):
    path = tmp_path / "bag_matches.json"
    path.write_text(
        json.dumps(
            {
                "kpts0": [1.0, 2.0, 3.0, 4.0],
                "kpts1": [5.0, 6.0],
                "matches": [0, -1],
                "confidence": [0.9, 0.01],
            }
        )
    )
    m = read_matches_json(path)
    assert m.num_matches == 1 and m.matcher == ""
    uv0, uv1, conf = m.matched()
    np.testing.assert_array_equal(uv0, [[1.0, 2.0]])
    np.testing.assert_array_equal(uv1, [[5.0, 6.0]])
    np.testing.assert_array_equal(conf, [0.9])


@pytest.mark.parametrize(
    "doc, words",
    [
        ("not json", "JSON"),
        ({"kpts0": [1.0, 2.0]}, "missing keys"),
        ({"kpts0": [1.0], "kpts1": [], "matches": [-1], "confidence": [0]}, "flat lists"),
        ({"kpts0": [1.0, 2.0], "kpts1": [], "matches": [3], "confidence": [0.5]}, "index"),
        ({"kpts0": [1.0, 2.0], "kpts1": [], "matches": [], "confidence": [0.5]}, "one entry"),
    ],
)
def test_bad_matches_files_are_user_errors(tmp_path, doc, words):
    path = tmp_path / "x_matches.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    with pytest.raises(InputError, match=words) as exc:
        read_matches_json(path)
    assert str(path) in str(exc.value)


def test_missing_matches_file_names_the_command(tmp_path):
    with pytest.raises(InputError, match="find-matches"):
        read_matches_json(tmp_path / "none_matches.json")


# -------------------------------------------------------------------- rotations


@pytest.mark.parametrize("degrees", [0, 90, 180, 270])
def test_unrotate_points_is_the_exact_inverse(degrees, rng):
    image = rng.integers(0, 2**31, size=(5, 8), dtype=np.int64)  # distinct values
    rotated = rotate_image(image, degrees)
    assert rotated.shape == (image.shape if degrees in (0, 180) else image.shape[::-1])
    vs, us = np.mgrid[0 : rotated.shape[0], 0 : rotated.shape[1]]
    uv_rot = np.column_stack([us.ravel(), vs.ravel()]).astype(float)
    uv = unrotate_points(uv_rot, degrees, (image.shape[1], image.shape[0]))
    # every pixel of the rotated image shows the original pixel it maps back to
    assert np.array_equal(uv, np.round(uv))
    ui, vi = uv[:, 0].astype(int), uv[:, 1].astype(int)
    np.testing.assert_array_equal(image[vi, ui], rotated[vs.ravel(), us.ravel()])


def test_rotation_is_clockwise_and_not_off_by_one():
    image = np.zeros((4, 6), np.uint8)
    image[0, 0] = 1  # top-left
    assert rotate_image(image, 90)[0, -1] == 1  # clockwise: top-left goes to top-right
    # a sub-pixel keypoint at the top-left corner's centre comes back to (0, 0): W - 1 - u
    np.testing.assert_allclose(unrotate_points([[5.0, 3.0]], 180, (6, 4)), [[0.0, 0.0]])
    np.testing.assert_allclose(unrotate_points([[3.0, 0.0]], 90, (6, 4)), [[0.0, 0.0]])
    np.testing.assert_allclose(unrotate_points([[0.0, 5.0]], 270, (6, 4)), [[0.0, 0.0]])


def test_bad_rotation_is_rejected():
    with pytest.raises(ValueError, match="clockwise"):
        rotate_image(np.zeros((4, 4), np.uint8), 45)


# -------------------------------------------------------------------- SIFT fallback


def test_sift_finds_correct_matches_on_a_warped_copy(warped_pair):
    image, warped, H = warped_pair
    k0, d0 = sift_features(image)
    k1, d1 = sift_features(warped)
    matches0, confidence = sift_match(d0, d1)
    m = Matches(k0, k1, matches0, confidence, matcher="sift")
    n_correct, fraction = correct_fraction(m, H)
    assert n_correct >= 50 and fraction >= 0.9, (n_correct, fraction)
    assert np.all((confidence >= 0) & (confidence <= 1))


def test_sift_on_a_blank_image_finds_nothing():
    k, d = sift_features(np.full((64, 64), 128, np.uint8))
    assert k.shape == (0, 2) and d.shape == (0, 128)
    matches0, confidence = sift_match(d, d)
    assert matches0.shape == (0,) and confidence.shape == (0,)


@pytest.mark.parametrize("rotate", [90, 180, 270])
def test_match_images_maps_rotated_keypoints_back(warped_pair, rotate):
    """The LiDAR image is stored rotated; matching with the inverse rotation finds the pairs
    and reports them in the stored (rotated) image's pixels."""
    image, warped, H = warped_pair
    stored = rotate_image(warped, rotate)
    m = match_images(
        image,
        stored,
        matcher="sift",
        rotate_lidar=(360 - rotate) % 360,
        camera_normalization="none",
        lidar_normalization="none",
        lidar_fill_radius=0,
    )
    assert m.matcher == "sift" and m.info["rotate_lidar"] == (360 - rotate) % 360
    assert np.all(m.kpts_lidar[:, 0] <= stored.shape[1] - 1)
    assert np.all(m.kpts_lidar[:, 1] <= stored.shape[0] - 1)
    # stored pixels -> warped pixels (stored = rotate_image(warped, rotate)), then check with H
    size = (warped.shape[1], warped.shape[0])
    kpts_warped = unrotate_points(m.kpts_lidar, rotate, size)
    back = Matches(m.kpts_camera, kpts_warped, m.matches, m.confidence)
    n_correct, fraction = correct_fraction(back, H)
    assert n_correct >= 50 and fraction >= 0.9, (n_correct, fraction)


def test_auto_falls_back_to_sift_and_says_so(no_learned_models, warped_pair, caplog):
    image, warped, _ = warped_pair
    assert available_matchers(no_learned_models) == ["sift"]
    with caplog.at_level(logging.WARNING):
        m = match_images(image, warped, matcher="auto", model_dir=no_learned_models)
    assert m.matcher == "sift"
    assert "nbcalib models export" in caplog.text


def test_asking_for_a_missing_learned_matcher_names_the_command(tmp_path, warped_pair):
    pytest.importorskip("onnxruntime")
    image, warped, _ = warped_pair
    with pytest.raises(InputError, match="nbcalib models export --models aliked-lightglue"):
        match_images(image, warped, matcher="aliked-lightglue", model_dir=tmp_path)


def test_match_images_checks_its_inputs(warped_pair):
    image, warped, _ = warped_pair
    with pytest.raises(ValueError, match="uint8"):
        match_images(image.astype(float), warped, matcher="sift")
    with pytest.raises(ValueError, match="matcher must be one of"):
        match_images(image, warped, matcher="superglue")
    with pytest.raises(ValueError, match="rotate_camera"):
        match_images(image, warped, matcher="sift", rotate_camera=30)


# -------------------------------------------------------------------- learned-matcher filter


def filter_matches_loops(scores: np.ndarray, threshold: float):
    """Slow reference: mutual best of the inner matrix, probability above the threshold."""
    inner = scores[:-1, :-1]
    m, _n = inner.shape
    matches0, scores0 = np.full(m, -1), np.zeros(m)
    for i in range(m):
        j = int(np.argmax(inner[i]))
        if int(np.argmax(inner[:, j])) == i:
            scores0[i] = np.exp(inner[i, j])
            if scores0[i] > threshold:
                matches0[i] = j
    return matches0, scores0


def test_filter_matches_equals_the_loop_reference(rng):
    for m, n in [(6, 9), (9, 6), (1, 1), (30, 30)]:
        logits = rng.normal(size=(m + 1, n + 1)) * 3
        log_p = logits - np.log(np.exp(logits).sum(axis=1, keepdims=True))
        for threshold in (0.0, 0.01, 0.2):
            got = filter_matches(log_p, threshold)
            want = filter_matches_loops(log_p, threshold)
            np.testing.assert_array_equal(got[0], want[0])
            np.testing.assert_allclose(got[1], want[1], **TOL["kernel_vs_reference"])


# -------------------------------------------------------------------- normalisations


def test_fill_holes_fills_only_within_the_radius():
    image = np.zeros((9, 9), np.uint8)
    image[4, 4] = 200
    filled = fill_holes(image, radius=2)
    rows, cols = np.nonzero(filled)
    assert np.abs(rows - 4).max() == 2 and np.abs(cols - 4).max() == 2
    assert set(np.unique(filled)) == {0, 200}
    np.testing.assert_array_equal(fill_holes(image, radius=0), image)
    # filled pixels keep their values
    image[0, 0] = 17
    assert fill_holes(image, radius=3)[0, 0] == 17


def test_gradient_normalisation_ignores_the_sign_of_edges(rng):
    """What makes it work across modalities: an inverted image gives the same picture."""
    image = textured_image(rng, 120, 160)
    a = normalize_image(image, "gradient").astype(int)
    b = normalize_image(normalize_image(image, "invert"), "gradient").astype(int)
    assert np.abs(a - b).max() <= 1  # float rounding of the blur before uint8 truncation
    assert a.max() == 255


@pytest.mark.parametrize("method", ["none", "equalize", "clahe", "invert", "gradient"])
def test_normalisations_keep_shape_and_type(method, rng):
    image = textured_image(rng, 64, 80)
    out = normalize_image(image, method)
    assert out.shape == image.shape and out.dtype == np.uint8
    with pytest.raises(ValueError, match="unknown normalisation"):
        normalize_image(image, "sharpen")


# -------------------------------------------------------------------- picture


def test_draw_matches_side_by_side(rng):
    camera = np.full((40, 60), 50, np.uint8)
    lidar = np.full((20, 20), 100, np.uint8)
    m = Matches([[10.0, 20.0], [30.0, 5.0]], [[10.0, 10.0]], [0, -1], [0.8, 0.0])
    picture = draw_matches(camera, lidar, m)
    assert picture.shape == (40, 120, 3) and picture.dtype == np.uint8
    # the right half is the LiDAR image scaled to the camera's size; the line adds colour
    coloured = (picture.max(axis=2) - picture.min(axis=2)) > 30
    assert coloured[20, 10] and coloured[20, 60 + 31]
    assert not coloured[5, 30]  # the unmatched keypoint's dot is grey


# -------------------------------------------------------------------- CLI


@pytest.fixture
def workdir(tmp_path, warped_pair):
    from nbcalib.camera import create_camera
    from nbcalib.preprocess.lidar_image import LidarImage
    from nbcalib.products import PairData
    from nbcalib.workdir import WorkDir, make_calib

    image, warped, _ = warped_pair
    wd = WorkDir(tmp_path / "work")
    wd.prepare()
    # a work directory as the reference writes one (no virtual camera recorded); the "LiDAR
    # image" is a warped copy of the camera image, each pixel showing a point of its own
    index = np.arange(warped.size, dtype=np.int32).reshape(warped.shape)
    points = np.random.default_rng(0).normal(size=(warped.size, 3))
    intensities = warped.reshape(-1) / 255.0
    wd.write_pair(PairData("000000", image, points, intensities, LidarImage(warped, index, None)))
    camera = create_camera("pinhole", [300, 300, 239.5, 179.5], [], 480, 360)
    wd.write_calib(make_calib(camera, ["000000"]))
    return wd


def test_find_matches_writes_json_and_picture(workdir, no_learned_models):
    from nbcalib.cli import main

    # --views 0: the stored LiDAR image, as the reference toolbox matches
    assert main(["-q", "find-matches", str(workdir.path), "--matcher", "auto", "--views", "0"]) == 0
    m = read_matches_json(workdir.matches_path("000000"))
    assert m.matcher == "sift" and m.num_matches >= 50
    # the file's LiDAR keypoints are whole pixels, each the pixel that shows its point
    np.testing.assert_array_equal(m.kpts_lidar, np.round(m.kpts_lidar))
    assert (workdir.path / "000000_matches.png").is_file()
    corr = workdir.read_correspondences(workdir.load_pair("000000"), search_radius=0.0)
    assert len(corr) == m.num_matches


def test_find_matches_without_preprocessing_is_a_user_error(tmp_path, capsys):
    from nbcalib.cli import main

    (tmp_path / "empty").mkdir()
    assert main(["find-matches", str(tmp_path / "empty"), "--matcher", "sift"]) == 2
    err = capsys.readouterr().err
    assert "calib.json" in err and "nbcalib preprocess" in err and err.count("\n") == 1


def test_models_list(tmp_path, capsys):
    from nbcalib.cli import main

    assert main(["models", "list", "--dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path) in out and "aliked-lightglue" in out and "not exported" in out
