"""`nbcalib evaluate`, the ground-truth file and nbcalib.metrics.pose_errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nbcalib.camera import create_camera
from nbcalib.cli import main
from nbcalib.errors import InputError
from nbcalib.io.calib_json import (
    AUTO_STAGE,
    FINAL_STAGE,
    MANUAL_STAGE,
    CalibFile,
    read_calib_json,
    values_from_T_camera_lidar,
    write_calib_json,
)
from nbcalib.io.ground_truth import read_ground_truth, write_ground_truth
from nbcalib.metrics import pose_errors

DATA = Path(__file__).parent / "data"

# the true extrinsic: camera looking along LiDAR x, slightly rotated and offset
T_LIDAR_CAMERA_TRUE = np.eye(4)
T_LIDAR_CAMERA_TRUE[:3, :3] = (
    Rotation.from_rotvec([0.01, -0.02, 0.03])
    * Rotation.from_matrix([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
).as_matrix()
T_LIDAR_CAMERA_TRUE[:3, 3] = [0.12, -0.05, 0.08]
T_CAMERA_LIDAR_TRUE = np.linalg.inv(T_LIDAR_CAMERA_TRUE)


def perturbed(angle_deg: float, offset_m) -> np.ndarray:
    """T_camera_lidar whose camera is rotated by angle_deg and whose centre moved by offset_m
    (in the LiDAR frame) from the truth: the errors evaluate must report, by construction."""
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    T_lidar_camera = T_LIDAR_CAMERA_TRUE.copy()
    R_delta = Rotation.from_rotvec(np.deg2rad(angle_deg) * axis).as_matrix()
    T_lidar_camera[:3, :3] = R_delta @ T_lidar_camera[:3, :3]
    T_lidar_camera[:3, 3] += offset_m
    return np.linalg.inv(T_lidar_camera)


def make_workdir(tmp_path, poses: dict) -> Path:
    workdir = tmp_path / "work"
    workdir.mkdir()
    calib = CalibFile(meta={"bag_names": ["pair0"]})
    calib.set_camera(create_camera("pinhole", [500.0, 500.0, 320.0, 240.0], [], 640, 480))
    for stage, T_camera_lidar in poses.items():
        calib.set_T_camera_lidar(stage, T_camera_lidar)
    write_calib_json(workdir / "calib.json", calib)
    return workdir


@pytest.fixture
def ground_truth(tmp_path) -> Path:
    path = tmp_path / "ground_truth.json"
    write_ground_truth(path, T_CAMERA_LIDAR_TRUE)
    return path


def run_cli(capsys, *argv):
    status = main(["evaluate", *map(str, argv)])
    out, err = capsys.readouterr()
    return status, out, err


# --------------------------------------------------------------------------- metrics
def test_pose_errors_by_construction():
    errors = pose_errors(perturbed(0.7, [0.03, -0.04, 0.0]), T_CAMERA_LIDAR_TRUE)
    assert set(errors) == {"translation_error_m", "rotation_error_deg"}
    assert errors["translation_error_m"] == pytest.approx(0.05, abs=1e-12)
    assert errors["rotation_error_deg"] == pytest.approx(0.7, abs=1e-9)
    zero = pose_errors(T_CAMERA_LIDAR_TRUE, T_CAMERA_LIDAR_TRUE)
    assert zero["translation_error_m"] == pytest.approx(0.0, abs=1e-12)
    assert zero["rotation_error_deg"] == pytest.approx(0.0, abs=1e-6)


def test_translation_error_is_the_camera_centre_not_t_camera_lidar():
    # a pure rotation of the camera about its own centre moves t of T_camera_lidar, not the centre
    T_est = perturbed(10.0, [0.0, 0.0, 0.0])
    assert np.linalg.norm(T_est[:3, 3] - T_CAMERA_LIDAR_TRUE[:3, 3]) > 0.01
    errors = pose_errors(T_est, T_CAMERA_LIDAR_TRUE)
    assert errors["translation_error_m"] == pytest.approx(0.0, abs=1e-12)
    assert errors["rotation_error_deg"] == pytest.approx(10.0, abs=1e-9)


# --------------------------------------------------------------------------- the command
def test_evaluate_prints_one_json_line(tmp_path, capsys, ground_truth):
    workdir = make_workdir(
        tmp_path,
        {
            AUTO_STAGE: perturbed(3.0, [0.2, 0.0, 0.0]),
            FINAL_STAGE: perturbed(0.25, [0.0, 0.006, -0.008]),
        },
    )
    status, out, err = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    assert status == 0, err
    lines = out.splitlines()
    assert len(lines) == 1 and out.endswith("\n")
    result = json.loads(lines[0])
    assert list(result) == ["translation_error_m", "rotation_error_deg", "stage"]
    assert result["stage"] == "T_lidar_camera"
    assert result["translation_error_m"] == pytest.approx(0.01, abs=1e-12)
    assert result["rotation_error_deg"] == pytest.approx(0.25, abs=1e-9)


def test_evaluate_judges_the_latest_initial_guess(tmp_path, capsys, ground_truth):
    manual, auto = perturbed(5.0, [0.1, 0, 0]), perturbed(1.0, [0, 0.02, 0])
    workdir = make_workdir(tmp_path, {MANUAL_STAGE: manual, AUTO_STAGE: auto})
    status, out, _ = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    result = json.loads(out)
    assert (status, result["stage"]) == (0, AUTO_STAGE)  # written after the manual guess
    assert result["rotation_error_deg"] == pytest.approx(1.0, abs=1e-9)
    assert result["translation_error_m"] == pytest.approx(0.02, abs=1e-12)

    calib = read_calib_json(workdir / "calib.json")
    calib.set_T_camera_lidar(MANUAL_STAGE, manual)  # the manual guess is now the latest
    write_calib_json(workdir / "calib.json", calib)
    status, out, _ = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    result = json.loads(out)
    assert (status, result["stage"]) == (0, MANUAL_STAGE)
    assert result["rotation_error_deg"] == pytest.approx(5.0, abs=1e-9)
    assert result["translation_error_m"] == pytest.approx(0.1, abs=1e-12)

    status, out, _ = run_cli(capsys, workdir, "--ground-truth", ground_truth, "--stage", AUTO_STAGE)
    result = json.loads(out)
    assert (status, result["stage"]) == (0, AUTO_STAGE)
    assert result["rotation_error_deg"] == pytest.approx(1.0, abs=1e-9)


def test_ground_truth_forms_agree(tmp_path, capsys):
    workdir = make_workdir(tmp_path, {FINAL_STAGE: perturbed(0.5, [0.0, 0.0, 0.03])})
    values = values_from_T_camera_lidar(T_CAMERA_LIDAR_TRUE)
    forms = {
        "quat_only.json": {"T_lidar_camera": values},
        "matrix_only.json": {"T_camera_lidar": T_CAMERA_LIDAR_TRUE.tolist()},
        "both.json": {"T_lidar_camera": values, "T_camera_lidar": T_CAMERA_LIDAR_TRUE.tolist()},
        "calib.json": {
            "camera": {
                "camera_model": "pinhole",
                "intrinsics": [1.0, 1.0, 0.0, 0.0],
                "distortion_coeffs": [],
            },
            "results": {"T_lidar_camera": values},
        },
        # printed to 6 decimals (like KITTI's calibration files): accepted and re-orthonormalised
        "rounded.json": {"T_camera_lidar": np.round(T_CAMERA_LIDAR_TRUE, 6).tolist()},
    }
    for name, data in forms.items():
        (tmp_path / name).write_text(json.dumps(data))
        np.testing.assert_allclose(
            read_ground_truth(tmp_path / name), T_CAMERA_LIDAR_TRUE, rtol=0, atol=2e-6
        )
        status, out, err = run_cli(capsys, workdir, "--ground-truth", tmp_path / name)
        assert status == 0, err
        result = json.loads(out)
        assert result["rotation_error_deg"] == pytest.approx(0.5, abs=1e-3), name
        assert result["translation_error_m"] == pytest.approx(0.03, abs=1e-5), name


def test_write_ground_truth_format(tmp_path, ground_truth):
    raw = json.loads(ground_truth.read_text())
    assert set(raw) == {"T_lidar_camera", "T_camera_lidar"}
    assert len(raw["T_lidar_camera"]) == 7
    assert np.array(raw["T_camera_lidar"]).shape == (4, 4)
    np.testing.assert_allclose(raw["T_camera_lidar"], T_CAMERA_LIDAR_TRUE, rtol=0, atol=1e-12)


def test_reference_calib_json_as_ground_truth(tmp_path, capsys):
    workdir = tmp_path / "work"
    workdir.mkdir()
    shutil.copy(DATA / "reference_calib.json", workdir / "calib.json")
    status, out, err = run_cli(capsys, workdir, "--ground-truth", DATA / "reference_calib.json")
    assert status == 0, err
    result = json.loads(out)
    assert result == {
        "translation_error_m": 0.0,
        "rotation_error_deg": pytest.approx(0.0, abs=1e-6),
        "stage": "T_lidar_camera",
    }


# --------------------------------------------------------------------------- errors: exit 2
def _bad_gt(tmp_path, name, text) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


ERRORS = {
    "no_workdir": (
        lambda tmp, gt: [tmp / "nope", "--ground-truth", gt],
        "work directory not found",
    ),
    "no_calib": (lambda tmp, gt: [tmp, "--ground-truth", gt], "no calib.json"),
    "gt_missing": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            tmp / "gt.json",
        ],
        "file not found",
    ),
    "no_result": (
        lambda tmp, gt: [make_workdir(tmp, {}), "--ground-truth", gt],
        "no result to evaluate",
    ),
    "stage_absent": (
        lambda tmp, gt: [
            make_workdir(tmp, {AUTO_STAGE: np.eye(4)}),
            "--ground-truth",
            gt,
            "--stage",
            FINAL_STAGE,
        ],
        "no result 'T_lidar_camera'",
    ),
    "gt_invalid_json": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            _bad_gt(tmp, "gt.json", "{"),
        ],
        "invalid JSON",
    ),
    "gt_disagree": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            _bad_gt(
                tmp,
                "gt.json",
                json.dumps(
                    {
                        "T_lidar_camera": values_from_T_camera_lidar(T_CAMERA_LIDAR_TRUE),
                        "T_camera_lidar": T_LIDAR_CAMERA_TRUE.tolist(),  # the inverse by mistake
                    }
                ),
            ),
        ],
        "disagree",
    ),
    "gt_not_rotation": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            _bad_gt(tmp, "gt.json", json.dumps({"T_camera_lidar": (2 * np.eye(4)).tolist()})),
        ],
        "last row|not a rotation",
    ),
    "gt_bad_shape": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            _bad_gt(
                tmp, "gt.json", json.dumps({"T_camera_lidar": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]})
            ),
        ],
        "4x4",
    ),
    "gt_no_pose": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            _bad_gt(tmp, "gt.json", json.dumps({"pose": [0, 0, 0, 0, 0, 0, 1]})),
        ],
        "no ground truth",
    ),
    "gt_calib_without_result": (
        lambda tmp, gt: [
            make_workdir(tmp, {FINAL_STAGE: np.eye(4)}),
            "--ground-truth",
            _bad_gt(tmp, "gt.json", json.dumps({"results": {AUTO_STAGE: [0, 0, 0, 0, 0, 0, 1]}})),
        ],
        "without results.T_lidar_camera",
    ),
    "calib_corrupt": (
        lambda tmp, gt: [_corrupt_workdir(tmp), "--ground-truth", gt],
        "invalid JSON",
    ),
}


def _corrupt_workdir(tmp: Path) -> Path:
    workdir = make_workdir(tmp, {FINAL_STAGE: np.eye(4)})
    (workdir / "calib.json").write_text('{"camera": ')
    return workdir


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_errors_exit_2_with_one_line(tmp_path, capsys, ground_truth, case):
    make_argv, message = ERRORS[case]
    status, out, err = run_cli(capsys, *make_argv(tmp_path, ground_truth))
    assert status == 2
    assert out == ""
    assert len(err.splitlines()) == 1, err
    assert err.startswith("nbcalib evaluate: error: ")
    assert "Traceback" not in err
    import re

    assert re.search(message, err), err


def test_usage_errors_exit_2(capsys, tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["evaluate", str(tmp_path)])  # --ground-truth is required
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "--ground-truth" in err and len(err.splitlines()) == 1


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit) as info:
        main(["evaluate", "--help"])
    assert info.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out and "nbcalib evaluate" in out and "--ground-truth" in out


def test_read_ground_truth_is_an_input_error_api(tmp_path):
    with pytest.raises(InputError, match=r"gt\.json: file not found"):
        read_ground_truth(tmp_path / "gt.json")


def test_real_data_ground_truth_files(real_data):
    # the normalised real-data calibrations: T_cam_lidar 4x4 printed to ~6 digits
    paths = sorted(real_data.glob("**/calib_normalized*.json"))
    assert {p.relative_to(real_data).as_posix() for p in paths} >= {
        "kitti_raw_2011_09_26/calib/calib_normalized_cam2rect.json",
        "pjlab/auto_calib/calib_normalized.json",
        "pjlab/manual_calib_0/calib_normalized.json",
    }
    for path in paths:
        T = read_ground_truth(path)
        raw = np.array(json.loads(path.read_text())["T_cam_lidar"])
        np.testing.assert_allclose(T, raw, rtol=0, atol=1e-5)
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), rtol=0, atol=1e-12)


def test_the_intrinsics_error_against_the_labs_true_camera(tmp_path, capsys, ground_truth):
    """Against 'synth --given-*' ground truth the line adds the camera's error; otherwise not."""
    workdir = make_workdir(tmp_path, {FINAL_STAGE: T_CAMERA_LIDAR_TRUE})
    status, out, _ = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    assert status == 0 and "focal_error_percent" not in out
    true = create_camera("pinhole", [490.0, 494.0, 317.0, 244.0], [], 640, 480)
    lab = json.loads(ground_truth.read_text())
    lab["intrinsics"] = {"rendered": true.to_dict(), "given": {}, "offset": {}}
    ground_truth.write_text(json.dumps(lab))
    status, out, err = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    assert status == 0, err
    result = json.loads(out)
    # the work directory's camera: fx = fy = 500, (320, 240)
    assert result["focal_error_percent"] == pytest.approx(100 * (500 / 492 - 1), rel=1e-12)
    assert result["center_error_px"] == pytest.approx(5.0, rel=1e-12)
    assert result["translation_error_m"] == pytest.approx(0.0, abs=1e-12)
    # a bag's camera_info names a pinhole plumb_bob: any two models with a focal length compare
    lab["intrinsics"]["rendered"] = create_camera("plumb_bob", [500, 500, 320, 240], [0] * 5,
                                                  640, 480).to_dict()  # fmt: skip
    ground_truth.write_text(json.dumps(lab))
    status, out, _ = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    assert status == 0 and json.loads(out)["focal_error_percent"] == 0.0
    lab["intrinsics"]["rendered"] = create_camera("equirectangular", [640, 480], [], 640, 480)
    lab["intrinsics"]["rendered"] = lab["intrinsics"]["rendered"].to_dict()
    ground_truth.write_text(json.dumps(lab))
    status, _, err = run_cli(capsys, workdir, "--ground-truth", ground_truth)
    assert status == 2 and "no focal length" in err and len(err.strip().splitlines()) == 1
