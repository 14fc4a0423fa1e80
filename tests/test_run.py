"""`nbcalib run`: every stage over one work directory, resuming, config files, stage checks."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.config import read_config_file
from nbcalib.io.calib_json import read_calib_json
from nbcalib.io.camera_file import save_camera
from nbcalib.io.image import write_png
from nbcalib.transforms import invert_T, pose_error, pose_to_xyz_quat, se3_exp
from tests.test_nid import textured_scene

#: The true extrinsic: a LiDAR with REP 103 axes (x forward) at the camera's centre
T_TRUE = np.array([[0.0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1]])
#: ~5 cm and ~1 degree from the truth: within reach of fine registration
T_START = se3_exp(np.array([0.04, -0.03, 0.02, 0.012, -0.008, 0.01])) @ T_TRUE
INIT = "--init=" + ",".join(f"{v:.9f}" for v in pose_to_xyz_quat(invert_T(T_START)))


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Plain files of one pair whose true extrinsic is the identity: points.npy (x, y, z,
    intensity), image.png and camera.yaml."""
    root = tmp_path_factory.mktemp("inputs")
    rng = np.random.default_rng(7)
    camera = example_camera("plumb_bob", 400, 300)
    image, points, intensities = textured_scene(camera, rng, n=20000, blur=2.5)
    points = points @ T_TRUE[:3, :3]  # camera frame -> LiDAR frame
    np.save(root / "points.npy", np.column_stack([points, intensities]).astype(np.float32))
    write_png(root / "image.png", np.round(image * 255).astype(np.uint8))
    save_camera(root / "camera.yaml", camera)
    return root


def _args(inputs, work, *extra):
    return [
        "run",
        str(inputs / "points.npy"),
        str(inputs / "image.png"),
        str(work),
        "--camera",
        str(inputs / "camera.yaml"),
        "--matcher",
        "sift",
        "--min-inliers",  # no automatic guess can pass: the --init fallback is certain
        "1000",
        "--max-outer",
        "2",
        "--no-report",
        *extra,
    ]


@pytest.fixture(scope="module")
def finished(inputs, tmp_path_factory):
    """A work directory after one `nbcalib run` that fell back to --init."""
    work = tmp_path_factory.mktemp("finished") / "work"
    assert main(_args(inputs, work, INIT)) == 0
    return work


def _copy(work, tmp_path):
    shutil.copytree(work, tmp_path / "work")
    return tmp_path / "work"


def test_run_calibrates_and_records_the_options(finished):
    calib = read_calib_json(finished / "calib.json")
    dt, dr = pose_error(invert_T(calib.get_T_camera_lidar("T_lidar_camera")), invert_T(T_TRUE))
    assert dt < 0.005 and dr < 0.05, (dt, dr)
    config = calib.to_dict()["nbcalib"]["config"]  # the whole config tree used
    assert config["matching"]["matcher"] == "sift"
    assert config["refine"]["max_outer"] == 2 and config["initial_guess"]["min_inliers"] == 1000
    assert calib.to_dict()["nbcalib"]["inputs"]["inputs"][0].endswith("points.npy")
    # what made each product is recorded (the resume decisions use it)
    assert {"preprocess", "find-matches", "initial-guess", "calibrate"} <= set(
        calib.to_dict()["nbcalib"]["made"]
    )
    # the YAML copy holds the same tree, and --config reads it back
    written = read_config_file(finished / "nbcalib_config.yaml")
    assert written["refine"]["max_outer"] == 2 and written["preprocess"]["voxel_size"] == 0.002
    assert written["inputs"]["camera"].endswith("camera.yaml")


def test_run_falls_back_to_init_and_says_so(finished):
    calib = read_calib_json(finished / "calib.json")
    assert not calib.has_result("init_T_lidar_camera_auto")
    assert calib.to_dict()["nbcalib"]["calibration"]["start"] == "--init"
    assert calib.to_dict()["nbcalib"]["run"]["init"] == INIT.split("=", 1)[1]
    assert calib.to_dict()["nbcalib"]["initial_guess"]["failed"]


def test_a_failed_automatic_guess_says_what_to_do_next(inputs, tmp_path, capsys):
    """No --init: the failed guess stops the run with exit 2, names the matcher and the three
    ways on (--init, --manual, --prior), and writes no guess."""
    work = tmp_path / "work"
    args = [a for a in _args(inputs, work) if a != INIT]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "initial guess not written" in err and "the sift matches" in err
    for way in ("--init X,Y,Z,QX,QY,QZ,QW", "--manual FILE", "--prior"):
        assert way in err, way
    # the progress log goes to stderr too; the error is one line, the last
    assert "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith("nbcalib run: error:")
    assert "initial guess not written" in err.strip().splitlines()[-1]
    calib = read_calib_json(work / "calib.json")
    assert not calib.has_result("init_T_lidar_camera_auto")
    assert not calib.has_result("T_lidar_camera")


def test_run_says_where_its_start_came_from(finished, capsys):
    """The summary of a resumed run names the start: --init, after the automatic guess failed."""
    assert main(["run", str(finished)]) == 0
    out = capsys.readouterr().out
    assert "started from: --init (the automatic initial guess failed: fewer than 1000" in out


def test_run_resumes_without_redoing_finished_stages(finished, tmp_path, caplog, capsys):
    work = _copy(finished, tmp_path)
    before = (work / "calib.json").read_text()
    caplog.set_level("INFO", logger="nbcalib")
    assert main(["run", str(work)]) == 0  # the inputs and options recorded in WORKDIR
    assert (work / "calib.json").read_text() == before
    for stage in ("preprocess", "find-matches", "initial-guess", "calibrate"):
        assert f"{stage}: skipped (done)" in caplog.text
    assert "ran nothing" in capsys.readouterr().out


def test_init_uncertainty_judges_the_move_and_restating_it_redoes_only_the_report(
    finished, tmp_path, caplog
):
    work = _copy(finished, tmp_path)
    calib = read_calib_json(work / "calib.json")
    calib.record.run.no_report = False  # the report this time
    (work / "calib.json").write_text(json.dumps(calib.to_dict()))
    caplog.set_level("INFO", logger="nbcalib")
    assert main(["run", str(work), "--init-uncertainty", "0.002", "0.05"]) == 0
    assert "calibrate: skipped (done)" in caplog.text
    calib = read_calib_json(work / "calib.json")
    assert calib.to_dict()["nbcalib"]["run"]["init_uncertainty"] == ["0.002", "0.05"]
    assert calib.to_dict()["nbcalib"]["calibration"]["start_uncertainty"] == {
        "translation_m": 0.002,
        "rotation_deg": 0.05,
    }
    move = calib.to_dict()["nbcalib"]["quality"]["move_from_start"]
    assert move["start_uncertainty"]["source"] == "stated"
    # ~5 cm and ~1 deg from a start stated to within 2 mm / 0.05 deg: too far
    assert any(r.startswith("moved ") for r in calib.to_dict()["nbcalib"]["quality"]["reasons"])
    caplog.clear()
    assert main(["run", str(work), "--init-uncertainty", "0.1", "2"]) == 0
    assert "calibrate: skipped (done)" in caplog.text
    assert "settings changed: start_uncertainty" in caplog.text
    quality = read_calib_json(work / "calib.json").to_dict()["nbcalib"]["quality"]
    assert not any(r.startswith("moved ") for r in quality["reasons"])
    assert quality["move_from_start"]["start_uncertainty"]["translation_m"] == 0.1


def test_run_continues_an_interrupted_job(finished, tmp_path, caplog):
    work = _copy(finished, tmp_path)
    calib = read_calib_json(work / "calib.json")
    del calib.results["T_lidar_camera"]
    del calib.record.made["calibrate"]
    (work / "calib.json").write_text(json.dumps(calib.to_dict()))
    caplog.set_level("INFO", logger="nbcalib")
    assert main(["run", str(work), "--max-outer", "1"]) == 0
    assert "preprocess: skipped (done)" in caplog.text
    assert "calibrate: skipped" not in caplog.text
    assert read_calib_json(work / "calib.json").has_result("T_lidar_camera")


def test_run_refuses_to_overwrite_a_finished_result(finished, inputs, tmp_path, capsys):
    work = _copy(finished, tmp_path)
    before = (work / "calib.json").read_text()
    assert main(_args(inputs, work, INIT, "--bins", "8")) == 2
    err = capsys.readouterr().err
    assert "finished result" in err and "--force" in err and "bins" in err
    assert len(err.strip().splitlines()) == 1
    assert (work / "calib.json").read_text() == before
    # --from calibrate: only calibrate runs again, with the new option
    assert main(["run", str(work), "--from", "calibrate", "--bins", "8", "--max-outer", "1"]) == 0
    calib = read_calib_json(work / "calib.json")
    assert calib.to_dict()["nbcalib"]["config"]["refine"]["bins"] == 8
    assert (
        calib.to_dict()["nbcalib"]["made"]["preprocess"]
        == read_calib_json(finished / "calib.json").to_dict()["nbcalib"]["made"]["preprocess"]
    )


def test_run_reads_a_config_file(inputs, tmp_path):
    config = tmp_path / "job.toml"
    config.write_text(
        f'camera = "{(inputs / "camera.yaml").as_posix()}"\n'
        "no_report = true\n"
        "[preprocess]\nvoxel-size = 0.01\nmin_distance = 0.5\n"
        '[find-matches]\nmatcher = "sift"\nno-picture = true\n'
    )
    work = tmp_path / "work"
    argv = ["run", str(inputs / "points.npy"), str(inputs / "image.png"), str(work)]
    # the command line wins over the file
    assert (
        main([*argv, "--config", str(config), "--voxel-size", "0.005", "--until", "find-matches"])
        == 0
    )
    calib = read_calib_json(work / "calib.json")
    used = calib.to_dict()["nbcalib"]["config"]
    assert used["preprocess"]["voxel_size"] == 0.005 and used["preprocess"]["min_distance"] == 0.5
    assert used["matching"]["matcher"] == "sift" and not used["matching"]["draw"]
    assert not (work / "000000_matches.png").exists()
    assert "calibrate" not in calib.to_dict().get("nbcalib", {})["made"]


@pytest.mark.parametrize(
    "text, message",
    [
        ("no_such_option = 1\n", "unknown option --no-such-option"),
        ("bins = 'many'\n", "refine.bins must be an integer"),
        ("[refine]\nbins = 1\n", "bins must be >= 2"),
        ("[matching]\nmatchr = 'sift'\n", "unknown option --matchr"),
        ("dynamic = 'yes'\n", "true or false"),
        ("[nonsense]\nbins = 3\n", "unknown table"),
        ("bins = \n", "invalid TOML"),
    ],
)
def test_bad_config_files_name_the_file(inputs, tmp_path, capsys, text, message):
    config = tmp_path / "job.toml"
    config.write_text(text)
    argv = ["run", str(inputs / "points.npy"), str(inputs / "image.png"), str(tmp_path / "w")]
    assert main([*argv, "--config", str(config)]) == 2
    err = capsys.readouterr().err
    assert message in err and str(config) in err and len(err.strip().splitlines()) == 1


def test_yaml_config_and_write_config_round_trip(tmp_path):
    from nbcalib.commands._options import file_settings
    from nbcalib.config import CalibrationConfig, config_from_dict, set_values, write_config

    config = set_values(
        CalibrationConfig(),
        {"preprocess.voxel_size": 0.01, "refine.bins": 8, "preprocess.odometry.knn": 12},
    )
    write_config(tmp_path / "c.yaml", config, {"inputs": {"inputs": ["a.bag"]}})
    data = read_config_file(tmp_path / "c.yaml")
    assert data["inputs"] == {"inputs": ["a.bag"]}
    assert config_from_dict({k: v for k, v in data.items() if k != "inputs"}) == config
    settings, other = file_settings(data, tmp_path / "c.yaml")
    assert settings["refine.bins"] == 8 and settings["preprocess.odometry.knn"] == 12
    assert other["inputs"] == {"inputs": ["a.bag"]}
    # the former names of the trust region (max_total_*) still read, with a warning
    old = {"refine": {"max_total_translation": 0.3}, "init-uncertainty": [0.05, 1.0]}
    settings, other = file_settings(old, tmp_path / "old.toml")
    assert settings == {"refine.trust_translation": 0.3}
    assert other == {"init_uncertainty": [0.05, 1.0]}
    (tmp_path / "twice.yaml").write_text("bins: 3\ncalibrate:\n  bins: 4\n")
    with pytest.raises(ValueError, match="given twice"):
        file_settings(read_config_file(tmp_path / "twice.yaml"), tmp_path / "twice.yaml")


def test_run_points_form_and_quiet(inputs, tmp_path, capsys):
    work = tmp_path / "work"
    argv = ["run", "--points", str(inputs / "points.npy"), str(work)]
    argv += ["--image", str(inputs / "image.png"), "--camera", str(inputs / "camera.yaml")]
    assert main([*argv, "--until", "preprocess", "-q"]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""
    assert read_calib_json(work / "calib.json").to_dict()["nbcalib"]["inputs"]["points"]


def test_run_user_errors(inputs, tmp_path, capsys):
    work = tmp_path / "work"
    assert main(["run", str(work), "--no-report"]) == 2
    assert "nothing to preprocess" in capsys.readouterr().err
    assert main([*_args(inputs, work), "--no-matching"]) == 2
    assert "--no-matching needs --init" in capsys.readouterr().err
    assert main(["run"]) == 2
    assert "WORKDIR missing" in capsys.readouterr().err


@pytest.mark.parametrize(
    "command, message",
    [
        (["find-matches"], "run 'nbcalib preprocess' first"),
        (["initial-guess"], "run 'nbcalib preprocess' first"),
        (["calibrate"], "run 'nbcalib preprocess' first"),
        (["report"], "run 'nbcalib preprocess' first"),
        (["evaluate", "--ground-truth", "gt.json"], "run 'nbcalib preprocess' first"),
    ],
)
def test_stages_name_the_stage_to_run_first_on_an_empty_workdir(tmp_path, capsys, command, message):
    (tmp_path / "work").mkdir()
    assert main([command[0], str(tmp_path / "work"), *command[1:]]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_stages_name_the_stage_to_run_first_after_preprocess(finished, tmp_path, capsys):
    work = _copy(finished, tmp_path)
    calib = read_calib_json(work / "calib.json")
    calib.results.clear()
    (work / "calib.json").write_text(json.dumps(calib.to_dict()))
    matches = [*work.glob("*_matches.json"), *work.glob("*_correspondences.json")]
    assert matches  # the finished run wrote them: removing them is what this test is about
    for path in matches:
        path.unlink()
    assert main(["initial-guess", str(work)]) == 2
    assert "run 'nbcalib find-matches' first" in capsys.readouterr().err
    assert main(["calibrate", str(work)]) == 2
    assert "run nbcalib initial-guess first" in capsys.readouterr().err


def test_run_help_lists_every_stage_option(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["run", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for option in ("--voxel-size", "--matcher", "--ransac-threshold", "--optimizer", "--config"):
        assert option in out
    assert "examples:" in out and "(default: 0.002)" in out
