"""`nbcalib.calibrate`: the whole pipeline from arrays or files, in a few lines."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import nbcalib
from nbcalib.camera import example_camera
from nbcalib.errors import InputError
from nbcalib.io.calib_json import read_calib_json
from nbcalib.io.image import write_png
from nbcalib.transforms import invert_T, pose_error, se3_exp
from tests.test_nid import textured_scene

#: The true extrinsic: a LiDAR with REP 103 axes (x forward) at the camera's centre
T_TRUE = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
#: ~5 cm and ~1 degree from the truth
T_START = se3_exp(np.array([0.04, -0.03, 0.02, 0.012, -0.008, 0.01])) @ T_TRUE


@pytest.fixture(scope="module")
def scene():
    """Camera, image (float in [0, 1]), points and intensities; the true extrinsic is the
    identity."""
    rng = np.random.default_rng(7)
    camera = example_camera("plumb_bob", 400, 300)
    image, points, intensities = textured_scene(camera, rng, n=20000, blur=2.5)
    points = points @ T_TRUE[:3, :3]  # camera frame -> LiDAR frame
    return camera, image, points, intensities


class _Handle:
    """What IPython's ``display(..., display_id=True)`` returns: the texts it was updated to."""

    def __init__(self, texts):
        self.texts = texts

    def update(self, bundle, raw=False):
        self.texts.append(bundle["text/plain"])


@pytest.fixture(scope="module")
def in_a_notebook(scene):
    """``calibrate`` as a learner calls it in a notebook, logging configured by nobody: what it
    printed (stdout) and the progress bars it displayed (their texts, in order)."""
    import logging

    import IPython.display

    import nbcalib.progress

    camera, image, points, intensities = scene
    printed, bars = io.StringIO(), []

    def display(bundle, raw=False, display_id=False):
        bars.append([bundle["text/plain"]])
        return _Handle(bars[-1])

    logger = logging.getLogger("nbcalib")
    assert logger.level == logging.NOTSET and not logger.handlers  # nothing configured
    with pytest.MonkeyPatch.context() as mp, contextlib.redirect_stdout(printed):
        mp.setattr(logger, "propagate", False)  # pytest's own handlers (on the root) cut off
        mp.setattr(nbcalib.progress, "in_jupyter", lambda: True)
        mp.setattr(IPython.display, "display", display)
        result = nbcalib.calibrate(points, intensities, image, camera, T_init=T_START, max_outer=2)
    assert logger.level == logging.NOTSET and not logger.handlers  # left as found
    return SimpleNamespace(result=result, printed=printed.getvalue(), bars=bars)


@pytest.fixture(scope="module")
def result(in_a_notebook):
    return in_a_notebook.result


def test_calibrate_shows_its_progress_in_a_notebook(in_a_notebook):
    """Stage lines as the command line's, printed (no stderr block), and bars updated in place."""
    lines = in_a_notebook.printed.splitlines()
    if lines[0].startswith("first run on this machine"):  # a cold numba cache says so first
        lines = lines[1:]
    assert lines[0].startswith("[1/") and "preprocess" in lines[0], lines[:3]
    assert any(line.startswith("    calibrate done in") for line in lines), "\n".join(lines)
    assert any(bar[0].startswith("quality") for bar in in_a_notebook.bars), in_a_notebook.bars


def test_calibrate_progress_lines_to_a_callable(scene):
    camera, image, points, intensities = scene
    lines = []
    nbcalib.calibrate(
        points,
        intensities,
        image,
        camera,
        T_init=T_START,
        max_outer=1,
        log=lines.append,
    )
    lines = [line for line in lines if not line.startswith("first run on this machine")]
    assert lines[0].startswith("[1/") and any("done in" in line for line in lines), lines


def test_calibrate_from_arrays_recovers_the_truth(result):
    dt, dr = pose_error(result.T_lidar_camera, invert_T(T_TRUE))
    assert dt < 0.005 and dr < 0.05, (dt, dr)
    np.testing.assert_allclose(result.T_lidar_camera @ result.T_camera_lidar, np.eye(4), atol=1e-12)
    # the start passes between stages as calib.json's seven numbers (nbcalib.products.Start)
    np.testing.assert_allclose(result.T_init, T_START, rtol=0, atol=1e-12)
    assert result.init_source == "T_init" and result.initial_guess is None
    assert len(result.xyz_quat) == 7
    assert "CalibrationResult(T_lidar_camera=" in repr(result)


def test_calibrate_reports_quality_figures(result):
    assert result.quality.verdict in ("ok", "suspect")


def test_calibrate_keeps_the_intermediate_products(result, scene):
    history = result.nid_history
    assert len(history) == len(result.refinement.history) + 1
    assert history[-1] < history[0]
    (pair,) = result.pairs
    assert pair.name == "000000" and result.matches == []  # T_init given: no matching
    assert pair.image.shape == (300, 400) and pair.image.dtype == np.uint8
    lidar = pair.lidar_image
    assert lidar.intensity.dtype == np.uint8 and pair.lidar_index.dtype == np.int32
    assert pair.lidar_index.shape == lidar.intensity.shape
    filled = pair.lidar_index[pair.lidar_index >= 0]
    assert filled.size > 1000 and filled.max() < len(pair.points_lidar)
    assert pair.points_lidar.shape == (len(pair.intensities), 3)
    assert np.all((pair.intensities >= 0) & (pair.intensities <= 1))


@pytest.mark.slow
def test_calibrate_from_files_and_several_pairs_into_a_workdir(scene, tmp_path):
    camera, image, points, intensities = scene
    np.save(tmp_path / "points.npy", np.column_stack([points, intensities]))
    write_png(tmp_path / "image.png", np.round(image * 255).astype(np.uint8))
    half = len(points) // 2
    result = nbcalib.calibrate(
        [tmp_path / "points.npy", points[half:]],
        [None, intensities[half:]],
        [str(tmp_path / "image.png"), np.round(image * 255).astype(np.uint8)],
        camera,
        T_init=T_START,
        workdir=tmp_path / "work",
        max_outer=2,
    )
    assert [p.name for p in result.pairs] == ["000000", "000001"]
    calib = read_calib_json(tmp_path / "work" / "calib.json")
    np.testing.assert_allclose(
        calib.get_T_camera_lidar("T_lidar_camera"), result.T_camera_lidar, atol=1e-6
    )
    assert calib.to_dict()["nbcalib"]["calibration"]["nid_history"] == result.nid_history


def test_calibrate_rejects_bad_input(scene, tmp_path):
    camera, image, points, intensities = scene
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        nbcalib.calibrate(points[:, :2], intensities, image, camera, T_init=T_START)
    with pytest.raises(ValueError, match="intensities must have shape"):
        nbcalib.calibrate(points, intensities[:-1], image, camera, T_init=T_START)
    with pytest.raises(ValueError, match="one image and one intensity array per cloud"):
        nbcalib.calibrate([points, points], intensities, image, camera, T_init=T_START)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        nbcalib.calibrate(points, intensities, image * 255, camera, T_init=T_START)
    with pytest.raises(InputError, match="image not found"):
        nbcalib.calibrate(points, intensities, tmp_path / "missing.png", camera, T_init=T_START)
    with pytest.raises(ValueError, match="T_init"):
        nbcalib.calibrate(points, intensities, image, camera, T_init=np.eye(3))


def test_the_api_is_a_lazy_attribute():
    code = (
        "import sys, nbcalib; f = nbcalib.calibrate; r = nbcalib.CalibrationResult; "
        "assert 'numba' not in sys.modules, 'numba imported'; print(f.__module__)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "nbcalib.api"
