"""`nbcalib calibrate` on a small work directory with a known answer."""

from __future__ import annotations

import json

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.io.calib_json import read_calib_json
from nbcalib.preprocess.lidar_image import (
    estimate_lidar_fov,
    make_virtual_camera,
    render_lidar_image,
)
from nbcalib.preprocess.workdir import WorkDir, make_calib
from nbcalib.transforms import invert_T, pose_error, pose_to_xyz_quat, se3_exp
from tests.test_nid import textured_scene


@pytest.fixture
def workdir(tmp_path):
    """One pair whose LiDAR intensities are a function of the image at the true projection
    (identity extrinsic): the NID minimum is at the truth."""
    rng = np.random.default_rng(7)
    cam = example_camera("plumb_bob", 400, 300)
    image, points, intensities = textured_scene(cam, rng, n=40000, blur=2.5)
    vcam, T_vcam_lidar = make_virtual_camera(estimate_lidar_fov(points))
    lidar_image = render_lidar_image(vcam, T_vcam_lidar, points, intensities)
    work = WorkDir(tmp_path / "work")
    work.prepare()
    work.write_pair(
        "000000",
        image=np.round(image * 255).astype(np.uint8),
        points_lidar=points,
        intensities=intensities,
        lidar_image=lidar_image,
    )
    work.write_calib(make_calib(cam, ["000000"]))
    return work


def test_calibrate_recovers_the_truth_from_init(workdir, capsys):
    T_start = se3_exp(np.array([0.04, -0.03, 0.02, 0.012, -0.008, 0.01]))  # ~5 cm, ~1 degree
    init = ",".join(f"{v:.9f}" for v in pose_to_xyz_quat(invert_T(T_start)))
    assert main(["calibrate", str(workdir.path), f"--init={init}"]) == 0
    calib = read_calib_json(workdir.calib_path)
    T = calib.get_T_camera_lidar("T_lidar_camera")
    dt, dr = pose_error(invert_T(T), np.eye(4))
    assert dt < 0.005 and dr < 0.05, (dt, dr)
    fig = calib.nbcalib["calibration"]
    assert fig["nid"] < fig["nid_start"] and fig["start"] == "--init"
    json.dumps(fig)
    err = capsys.readouterr().err
    assert "outer 1: NID" in err


def test_calibrate_starts_from_the_initial_guess_in_calib_json(workdir):
    calib = read_calib_json(workdir.calib_path)
    calib.set_T_camera_lidar(
        "init_T_lidar_camera_auto", se3_exp(np.array([0.02, 0, 0, 0, 0.005, 0]))
    )
    workdir.write_calib(calib)
    assert main(["calibrate", str(workdir.path), "--max-outer", "3"]) == 0
    calib = read_calib_json(workdir.calib_path)
    assert calib.nbcalib["calibration"]["start"] == "init_T_lidar_camera_auto"


@pytest.mark.parametrize(
    "args, message",
    [
        (["--init", "1,2,3"], "7 numbers"),
        (["--init", "a,b,c,d,e,f,g"], "7 numbers"),
        ([], "no initial guess"),
        (["--pairs", "0", "--init", "0,0,0,0,0,0,1"], "--pairs"),
    ],
)
def test_calibrate_user_errors(workdir, capsys, args, message):
    assert main(["calibrate", str(workdir.path), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_calibrate_without_preprocessing(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path)]) == 2
    assert "run nbcalib preprocess first" in capsys.readouterr().err
