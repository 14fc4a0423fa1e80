"""A work directory as the reference C++ toolbox writes it, read as the reference means it.

The directory comes from :func:`reference_workdir.write_reference_workdir` (Iridescence PLY,
``calib.json`` without nbcalib's section, truncating LiDAR images of the reference's virtual
camera, SuperGlue matches). Every stage of the command line runs on it; the reference's
reader of ``<name>_matches.json`` is emulated on what nbcalib writes; and the match picture is
checked to draw the camera-shaped views' matches where their points are.
"""

from __future__ import annotations

import json
import logging
import shutil

import cv2
import numpy as np
import pytest
from conftest import hide_learned_models
from reference_workdir import IRIDESCENCE_PLY_HEADER, write_reference_workdir

from nbcalib.cli import main
from nbcalib.io.calib_json import AUTO_STAGE, FINAL_STAGE
from nbcalib.metrics import pose_errors
from nbcalib.workdir import WorkDir, get_virtual_camera

#: Files of the reference's preprocess (and SuperGlue script) that nbcalib only reads.
REFERENCE_FILES = ("{}.ply", "{}.png", "{}_lidar_intensities.png", "{}_lidar_indices.png")


@pytest.fixture(scope="module")
def no_models(tmp_path_factory):
    """No learned matcher for the whole module: matching runs SIFT."""
    with pytest.MonkeyPatch.context() as mp:
        yield hide_learned_models(mp, tmp_path_factory.mktemp("no-models"))


@pytest.fixture(scope="module")
def livox(tmp_path_factory):
    """A 70-degree LiDAR: the reference's pinhole virtual camera."""
    return write_reference_workdir(tmp_path_factory.mktemp("reference") / "livox")


@pytest.fixture(scope="module")
def spinning(tmp_path_factory):
    """A 360-degree LiDAR: the reference's equirectangular virtual camera."""
    return write_reference_workdir(
        tmp_path_factory.mktemp("reference") / "spinning", lidar="spinning"
    )


def _copy(ref, tmp_path):
    return shutil.copytree(ref.path, tmp_path / ref.path.name)


def reference_reader(work: WorkDir, name: str) -> list[tuple[int, int]]:
    """``initial_guess_auto``'s ``read_correspondences``: (match number, point row) of each match
    it uses. Keypoints are read as ints (truncated), the index map is looked up there, and a
    match on an empty pixel is dropped (its neighbour search is dead code)."""
    index = cv2.imread(str(work.lidar_index_path(name)), cv2.IMREAD_UNCHANGED).view("<i4")[..., 0]
    doc = json.loads(work.matches_path(name).read_text())
    kpts1 = [int(x) for x in doc["kpts1"]]
    used = []
    for i, j in enumerate(doc["matches"]):
        if j < 0:
            continue
        row = int(index[kpts1[2 * j + 1], kpts1[2 * j]])
        if row >= 0:
            used.append((i, row))
    return used


def assert_reference_reads_nbcalibs_points(work: WorkDir, name: str) -> int:
    """Every match nbcalib wrote lands, through the reference's reader, on the point of the
    correspondence it stands for; returns how many were written."""
    corr = json.loads(work.correspondences_path(name).read_text())
    rows = np.array(corr["point_index"])
    uv = np.array(corr["uv_camera"]).reshape(-1, 2)
    doc = json.loads(work.matches_path(name).read_text())
    assert all(type(x) is int for x in doc["kpts1"]), "LiDAR keypoints are whole pixels"
    # the correspondences whose point the stored LiDAR image shows are written, in order
    index = cv2.imread(str(work.lidar_index_path(name)), cv2.IMREAD_UNCHANGED).view("<i4")[..., 0]
    shown = np.isin(rows, index[index >= 0])
    written = np.array(doc["kpts0"], dtype=np.float64).reshape(-1, 2)
    np.testing.assert_array_equal(written, uv[shown])
    assert np.all(np.array(doc["matches"]) >= 0)
    used = reference_reader(work, name)
    assert len(used) == len(written), "no match lands on an empty pixel"
    got = np.array([row for _, row in used])
    np.testing.assert_array_equal(got, rows[shown][[i for i, _ in used]])
    return len(written)


# -------------------------------------------------------------------- the directory itself


def test_the_directory_is_written_as_the_reference_writes_it(livox):
    from nbcalib.io.index_map import read_index_map

    work, name = WorkDir(livox.path), livox.name
    data = work.cloud_path(name).read_bytes()
    header = IRIDESCENCE_PLY_HEADER.format(n=len(livox.points)).encode()
    assert data.startswith(header) and len(data) == len(header) + 16 * len(livox.points)
    calib = json.loads(work.calib_path.read_text())
    assert sorted(calib) == ["camera", "meta"], "no nbcalib section, no results yet"
    np.testing.assert_array_equal(read_index_map(work.lidar_index_path(name)), livox.index)
    matches = json.loads(work.matches_path(name).read_text())
    assert all(float(x).is_integer() for x in matches["kpts0"] + matches["kpts1"])
    pair = work.load_pair(name)  # nbcalib reads every product
    np.testing.assert_array_equal(pair.points_lidar, livox.points)
    np.testing.assert_array_equal(pair.intensities, livox.intensities)
    assert work.is_complete()


# -------------------------------------------------------------------- the virtual camera


@pytest.mark.parametrize("kind", ["livox", "spinning"])
def test_the_reference_virtual_camera_is_recovered_read_only(kind, request, caplog):
    from nbcalib.preprocess.lidar_image import render_lidar_image

    ref = request.getfixturevalue(kind)
    work = WorkDir(ref.path)
    before = {p.name: p.read_bytes() for p in ref.path.iterdir()}
    with caplog.at_level(logging.INFO, logger="nbcalib"):
        virtual = get_virtual_camera(work.read_calib())
    assert "recovered" in caplog.text and "WARNING" not in caplog.text
    np.testing.assert_allclose(virtual.T_vcam_lidar[:3, :3], ref.R_lidar_vcam.T, atol=1e-15)
    camera = virtual.camera
    if kind == "livox":
        fx = ref.vcam_intrinsics[0]
        assert (camera.model, camera.width, camera.height) == ("pinhole", 1024, 1024)
        # the reference's cx = cy = 512 under its truncation is 511.5 with centres at integers
        np.testing.assert_allclose(camera.intrinsics, [fx, fx, 511.5, 511.5], rtol=1e-5)
    else:
        assert (camera.model, camera.width, camera.height) == ("equirectangular", 1920, 960)
    # nbcalib's rendering through it is the reference's LiDAR image
    index = render_lidar_image(camera, virtual.T_vcam_lidar, ref.points, ref.intensities).index
    filled = ref.index >= 0
    assert np.mean(index[filled] == ref.index[filled]) > 0.99
    assert {p.name: p.read_bytes() for p in ref.path.iterdir()} == before, "nothing written"


def test_an_unknown_lidar_image_says_the_virtual_camera_is_unknown(livox, tmp_path, caplog):
    work = WorkDir(_copy(livox, tmp_path))
    bgra = cv2.imread(str(work.lidar_index_path(livox.name)), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(work.lidar_index_path(livox.name)), bgra[:900, :1000])
    with caplog.at_level(logging.WARNING, logger="nbcalib"):
        assert get_virtual_camera(work.read_calib()) is None
    assert "calib.json records no virtual camera" in caplog.text
    assert "_lidar_indices.png" in caplog.text and "1000 x 900" in caplog.text


# -------------------------------------------------------------------- the stages


def test_initial_guess_reads_the_reference_superglue_matches(livox, tmp_path, no_models):
    work = WorkDir(_copy(livox, tmp_path))
    # reading the reference's matches is the subject: on this small scene they bound the pose
    # to 0.14 deg, which the default precision test (times 8 for learned matches' shared error)
    # doubts; a guess whose matches found the pose is still written (fine registration refines
    # it, the report judges the end), and calib.json records the doubt
    assert main(["-q", "initial-guess", str(work.path)]) == 0
    figures = work.read_calib().record.guess().stages[AUTO_STAGE].values
    assert figures["precise"] is False and figures["success"] is False, figures
    assert main(["-q", "initial-guess", str(work.path), "--precision-scale", "0"]) == 0
    figures = work.read_calib().record.guess().stages[AUTO_STAGE].values
    assert figures["precise"] is True and figures["success"] is True, figures
    e = pose_errors(work.read_calib().get_T_camera_lidar(AUTO_STAGE), livox.T_camera_lidar)
    assert e["translation_error_m"] < 0.02 and e["rotation_error_deg"] < 0.2, e


def test_matching_the_stored_lidar_image_uses_the_recovered_camera(
    livox, tmp_path, no_models, caplog
):
    from nbcalib.matching.match import camera_scale_for

    work = WorkDir(_copy(livox, tmp_path))
    with caplog.at_level(logging.WARNING, logger="nbcalib"):
        argv = ["-q", "find-matches", str(work.path), "--matcher", "sift", "--views", "0"]
        assert main(argv) == 0
    assert "unknown" not in caplog.text
    doc = json.loads(work.matches_path(livox.name).read_text())
    virtual = get_virtual_camera(work.read_calib())
    scale = camera_scale_for(livox.camera, virtual.camera)
    assert doc["nbcalib"]["mode"] == "lidar_image"
    assert doc["nbcalib"]["camera_scale"] == pytest.approx(scale)
    assert assert_reference_reads_nbcalibs_points(work, livox.name) > 0


@pytest.fixture(scope="module")
def matched(livox, tmp_path_factory, no_models):
    """The livox directory after ``nbcalib find-matches`` (camera-shaped views)."""
    path = shutil.copytree(livox.path, tmp_path_factory.mktemp("matched") / "work")
    assert main(["-q", "find-matches", str(path), "--matcher", "sift"]) == 0
    return WorkDir(path)


def test_the_reference_reader_finds_the_points_nbcalib_matched(matched, livox):
    """The views' LiDAR keypoints are written at the stored image's pixels of their points."""
    n_written = assert_reference_reads_nbcalibs_points(matched, livox.name)
    n_corr = len(json.loads(matched.correspondences_path(livox.name).read_text())["point_index"])
    assert n_written > 0.5 * n_corr


def test_every_stage_runs_on_a_reference_workdir(matched, livox, tmp_path, no_models):
    work = WorkDir(shutil.copytree(matched.path, tmp_path / "work"))
    original = {f.format(livox.name): (livox.path / f.format(livox.name)).read_bytes()
                for f in REFERENCE_FILES}  # fmt: skip
    for argv in (["initial-guess"], ["calibrate", "--max-outer", "3"], ["report"], ["export"]):
        assert main(["-q", argv[0], str(work.path), *argv[1:]]) == 0, argv
    for name, data in original.items():
        assert (work.path / name).read_bytes() == data, f"{name} was changed"
    calib = json.loads(work.calib_path.read_text())
    reference = json.loads((livox.path / "calib.json").read_text())
    assert calib["camera"] == reference["camera"] and calib["meta"] == reference["meta"]
    assert all(len(calib["results"][k]) == 7 for k in (AUTO_STAGE, FINAL_STAGE))
    e = pose_errors(work.read_calib().get_T_camera_lidar(FINAL_STAGE), livox.T_camera_lidar)
    assert e["translation_error_m"] < 0.02 and e["rotation_error_deg"] < 0.2, e
    assert (work.path / "report" / "index.html").is_file()
    assert (work.path / "export" / "camera_lidar_opencv.yaml").is_file()


# -------------------------------------------------------------------- the match picture


def test_the_match_picture_draws_view_matches_where_their_points_are(spinning, tmp_path, no_models):
    """Matches of camera-shaped views are drawn on a view, not crowded into the panorama."""
    from nbcalib.matching.config import MatchConfig
    from nbcalib.matching.draw import picture_matches
    from nbcalib.matching.find import find_correspondences
    from nbcalib.transforms import transform_points

    work = WorkDir(_copy(spinning, tmp_path))
    pair = work.load_pair(spinning.name)
    found = find_correspondences(spinning.camera, pair, MatchConfig(matcher="sift", views=6))
    work.write_matches(found, pair)
    assert_reference_reads_nbcalibs_points(work, spinning.name)
    width, height = spinning.camera.width, spinning.camera.height

    def ends(matches, lidar_image):
        """The lines' LiDAR ends on the picture (its right half scaled to the camera's size)."""
        h, w = lidar_image.shape
        uv0, uv1, _ = matches.matched()
        return uv0, (uv1 + 0.5) * [width / w, height / h] - 0.5

    picture, m = picture_matches(found, pair.lidar_image.intensity)
    assert picture.shape != pair.lidar_image.intensity.shape, "a view, not the panorama"
    assert m.num_matches > 0.5 * len(found.correspondences)
    uv_camera, uv_end = ends(m, picture)
    assert np.all(np.std(uv_end, axis=0) > 0.5 * np.std(uv_camera, axis=0)), "spread"
    # each line ends where the view shows its point: the picture there has the point's value
    corr = found.correspondences
    view = next(v.view for v in found.views.views if v.view.intensity is picture)
    _, drawn = view.camera.project(
        transform_points(view.T_vcam_lidar, corr.points_lidar), in_image=True
    )
    u, v = np.floor(m.kpts_lidar + 0.5).astype(int).T
    value = 255.0 * pair.intensities[corr.point_index[drawn]]
    assert np.mean(np.abs(picture[v, u] - value) <= 1.0) > 0.9
    # the stored panorama would have crowded them into a patch a fifth of the picture wide
    uv_camera, uv_end = ends(found.matches, pair.lidar_image.intensity)
    assert np.std(uv_end[:, 0]) < 0.35 * np.std(uv_camera[:, 0])
    assert work.matches_picture_path(spinning.name).is_file()
