"""The lab of issue 47: synth hands the calibrator intrinsics other than the rendering camera's
(nbcalib.synthetic.intrinsics, nbcalib synth --given-*), with the truth of both kept."""

from __future__ import annotations

import json

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from nbcalib.camera import CAMERA_MODELS, example_camera
from nbcalib.cli import main
from nbcalib.io.camera_file import load_camera
from nbcalib.io.image import read_image
from nbcalib.synthetic import RigConfig, lidar_preset
from nbcalib.synthetic.intrinsics import GivenIntrinsics
from nbcalib.synthetic.writer import export_dataset

OFFSET = GivenIntrinsics(focal_scale=1.015, center_shift=(5.0, -3.0), distortion_scale=1.2)


@pytest.mark.parametrize("model", [m for m in CAMERA_MODELS if m != "equirectangular"])
def test_the_offset_moves_focal_center_and_distortion_of_every_model(model):
    true = example_camera(model, 640, 480)
    given = OFFSET.apply(true)
    assert given.model == model and (given.width, given.height) == (640, 480)
    assert_allclose(given.intrinsics[:2], 1.015 * true.intrinsics[:2], rtol=1e-15)
    assert_allclose(given.intrinsics[2:4], np.add(true.intrinsics[2:4], (5.0, -3.0)), rtol=1e-15)
    assert_array_equal(given.intrinsics[4:], true.intrinsics[4:])  # omnidir's xi stays
    assert_allclose(given.distortion_coeffs, 1.2 * true.distortion_coeffs, rtol=1e-15)
    assert GivenIntrinsics().apply(true).to_dict() == true.to_dict()


def test_what_cannot_be_offset_is_refused():
    assert GivenIntrinsics().exact and not OFFSET.exact
    with pytest.raises(ValueError, match="equirectangular camera's intrinsics are its image"):
        OFFSET.apply(example_camera("equirectangular", 640, 320))
    for bad in ({"focal_scale": 0.0}, {"focal_scale": float("nan")}, {"center_shift": (1.0,)}):
        with pytest.raises(ValueError):
            GivenIntrinsics(**bad)


def _config(**kw) -> RigConfig:
    return RigConfig(
        lidar="spinning16",
        camera="plumb_bob",
        image_size=(96, 72),
        duration=0.3,
        lidar_config=lidar_preset("spinning16", columns=180),
        seed=3,
        **kw,
    )


@pytest.mark.parametrize("fmt", ["files", "bag2"])
def test_the_user_gets_the_offset_camera_and_the_truth_keeps_both(tmp_path, fmt):
    from nbcalib.io.bag import read_camera_info, read_images

    exact = export_dataset(_config(), tmp_path / "exact", fmt=fmt)
    truth = export_dataset(_config(), tmp_path / "given", fmt=fmt, given=OFFSET)
    true_camera = load_camera(tmp_path / "exact" / "camera.yaml")
    given_camera = load_camera(tmp_path / "given" / "camera.yaml")
    assert given_camera.to_dict() == OFFSET.apply(true_camera).to_dict()
    written = json.loads((tmp_path / "given" / "ground_truth.json").read_text())
    assert written["intrinsics"] == truth["intrinsics"]
    assert truth["intrinsics"] == {
        "rendered": true_camera.to_dict(),
        "given": given_camera.to_dict(),
        "offset": OFFSET.to_dict(),
    }
    assert "intrinsics" not in exact  # exact intrinsics: ground_truth.json as before
    assert truth["T_lidar_camera"] == exact["T_lidar_camera"]
    if fmt == "files":  # the image is the true camera's, whatever the user is given
        images = [read_image(tmp_path / d / "pair_000.png") for d in ("exact", "given")]
    else:
        bags = [tmp_path / d / "pair_000" for d in ("exact", "given")]
        assert read_camera_info(bags[1]).to_dict() == given_camera.to_dict()
        images = [next(iter(read_images(bag)))[1] for bag in bags]
    assert_array_equal(*images)


def test_synth_takes_the_offset_on_the_command_line(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["synth", str(out), "--lidar", "spinning16", "--camera", "fisheye", "--seed", "2"]
    args += ["--duration", "0.2", "--image-size", "96x72"]
    given = ["--given-focal-scale", "0.99", "--given-center-shift", "-2.5,4"]
    assert main([*args, *given, "--given-distortion-scale", "0.5"]) == 0
    truth = json.loads((out / "ground_truth.json").read_text())
    assert truth["intrinsics"]["offset"] == {
        "focal_scale": 0.99,
        "center_shift": [-2.5, 4.0],
        "distortion_scale": 0.5,
    }
    rendered = np.asarray(truth["intrinsics"]["rendered"]["intrinsics"])
    camera = load_camera(out / "camera.yaml")
    assert_allclose(
        camera.intrinsics[:4], np.r_[0.99 * rendered[:2], np.add(rendered[2:4], (-2.5, 4.0))]
    )


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--camera", "equirectangular", "--given-focal-scale", "1.01"], "equirectangular"),
        (["--cameras", "pinhole,fisheye", "--given-focal-scale", "1.01"], "not --cameras"),
        (["--given-center-shift", "5"], "takes DX,DY"),
        (["--given-focal-scale", "-1"], "focal_scale must be > 0"),
    ],
)
def test_offsets_that_cannot_be_are_one_line_errors(tmp_path, capsys, extra, message):
    out = tmp_path / "out"
    assert main(["synth", str(out), *extra]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert "--given-*" in err and message in err
    assert not (out / "ground_truth.json").exists()
