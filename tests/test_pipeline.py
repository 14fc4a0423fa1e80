"""One pipeline: the demo, `nbcalib run` and `nbcalib.calibrate` give the same pose, bit for bit.

All three doors run :class:`nbcalib.pipeline.Calibrator` (the demo and `run` through a work
directory, the API in memory), so on the same input, settings and start their results must be
identical to the last bit, and the quality figures with them.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import nbcalib
from nbcalib.cli import main
from nbcalib.io.calib_json import read_calib_json
from nbcalib.products import Start

#: A small demo: one pair as plain files, a 320 x 240 image, half a second of Livox data.
DEMO = ["--pairs", "1", "--image-size", "320x240", "--duration", "0.5", "--matcher", "sift"]


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    root = tmp_path_factory.mktemp("demo") / "demo"
    assert main(["-q", "demo", str(root), *DEMO]) == 0
    return root


def test_the_demo_the_command_line_and_the_api_agree_bit_for_bit(demo, tmp_path, monkeypatch):
    from nbcalib.commands.demo import demo_inputs

    monkeypatch.setenv("NBCALIB_MODEL_DIR", str(tmp_path / "no-models"))
    summary = json.loads((demo / "demo_summary.json").read_text())
    spec = demo_inputs(demo / "synth", 1)
    values = summary["start_T_lidar_camera"]  # None when the demo's automatic guess was used
    start = ["--no-matching", "--init=" + ",".join(repr(v) for v in values)] if values else []

    # the command line, as a user types it
    work = tmp_path / "work"
    argv = ["-q", "run", *spec.inputs, str(work), "--camera", spec.camera, "--voxel-size", "0.02"]
    assert main([*argv, "--matcher", "sift", *start]) == 0
    cli = read_calib_json(work / "calib.json")

    # the API, in memory
    api = nbcalib.calibrate(
        list(spec.inputs[:-1]) if len(spec.inputs) > 2 else spec.inputs[0],
        None,
        spec.inputs[-1],
        spec.camera,
        T_init=None if values is None else Start.from_values(values, "T_init"),
        voxel_size=0.02,
        matcher="sift",
    )

    demo_calib = read_calib_json(demo / "work" / "calib.json")
    assert summary["T_lidar_camera"] == demo_calib.results["T_lidar_camera"]
    assert cli.results["T_lidar_camera"] == demo_calib.results["T_lidar_camera"]
    assert api.xyz_quat == cli.results["T_lidar_camera"]
    np.testing.assert_array_equal(api.T_camera_lidar, cli.get_T_camera_lidar("T_lidar_camera"))
    # the same history and the same judgement
    assert api.nid_history == cli.to_dict()["nbcalib"]["calibration"]["nid_history"]
    assert api.quality.verdict == cli.to_dict()["nbcalib"]["quality"]["verdict"]
    assert api.quality.uncertainty == cli.to_dict()["nbcalib"]["quality"]["uncertainty"]


def test_a_stage_run_by_hand_gives_the_pipelines_result(demo, tmp_path):
    """`nbcalib calibrate WORKDIR` on the demo's work directory repeats its fine registration."""
    import shutil

    work = tmp_path / "work"
    shutil.copytree(demo / "work", work)
    before = read_calib_json(work / "calib.json")
    summary = json.loads((demo / "demo_summary.json").read_text())
    init = summary["start_T_lidar_camera"]
    extra = ["--init=" + ",".join(repr(v) for v in init)] if init else []
    assert main(["-q", "calibrate", str(work), *extra]) == 2  # not over a result by accident
    assert main(["-q", "calibrate", str(work), *extra, "--force"]) == 0
    after = read_calib_json(work / "calib.json")
    assert after.results["T_lidar_camera"] == before.results["T_lidar_camera"]
    # the report described the old result: it is gone, not stale
    assert not (work / "report").exists() and "quality" not in after.to_dict().get("nbcalib", {})


def test_the_api_finds_its_own_initial_guess():
    """No T_init: matching (camera-shaped views, SIFT) and the initial guess run in memory."""
    from nbcalib.metrics import pose_errors
    from tests.test_matching_multiview import _self_consistent_pair

    camera, image, points, intensities, truth = _self_consistent_pair(
        np.random.default_rng(3), 60.0
    )
    result = nbcalib.calibrate(
        points,
        intensities,
        image,
        camera,
        matcher="sift",
        camera_normalization="none",
        lidar_normalization="none",
        views=6,
        max_outer=2,
    )
    assert result.init_source == "init_T_lidar_camera_auto"
    assert result.initial_guess is not None and result.initial_guess.success
    (found,) = result.matches
    assert len(found.correspondences) >= 20
    guess = pose_errors(result.T_init, truth)
    assert guess["rotation_error_deg"] < 1.0 and guess["translation_error_m"] < 0.1, guess
    final = pose_errors(result.T_camera_lidar, truth)
    assert final["rotation_error_deg"] < 0.5 and final["translation_error_m"] < 0.05, final


def test_a_work_directory_of_the_reference_toolbox_is_read_as_it_means(demo, tmp_path, capsys):
    """No nbcalib records: products are kept, matches.json is lifted, the report still runs."""
    import shutil

    work = tmp_path / "work"
    shutil.copytree(demo / "work", work)
    for path in [*work.glob("*_correspondences.json"), *work.glob("*_matches.png")]:
        path.unlink()
    shutil.rmtree(work / "report")
    (work / "nbcalib_config.yaml").unlink()
    calib = json.loads((work / "calib.json").read_text())
    reference = {key: calib[key] for key in ("camera", "meta", "results")}
    # a start picked by hand (the reference's GUI), and the result calibrate made from it
    reference["results"] = {
        "init_T_lidar_camera": calib["nbcalib"]["calibration"]["start_T_lidar_camera"],
        "T_lidar_camera": calib["results"]["T_lidar_camera"],
    }
    (work / "calib.json").write_text(json.dumps(reference, indent=2, sort_keys=True))

    # resuming keeps what the directory holds and says it was not made by nbcalib
    assert main(["run", str(work), "--no-report"]) == 0
    err = capsys.readouterr().err
    assert "preprocess: skipped (done, made without nbcalib)" in err
    assert "calibrate: skipped (done, made without nbcalib)" in err
    # the report needs no start pose
    assert main(["-q", "report", str(work)]) == 0
    assert (work / "report" / "index.html").is_file()
    # the initial guess reads the reference's matches.json through the index map
    assert main(["-q", "initial-guess", str(work), "--force"]) == 0
    out = capsys.readouterr().out
    assert "matches" in out and "init_T_lidar_camera_auto" in out
