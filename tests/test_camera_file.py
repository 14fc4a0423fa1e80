"""Camera files: ROS camera_info, OpenCV FileStorage, nbcalib YAML/JSON, calib.json."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from nbcalib.camera import CAMERA_MODELS, create_camera
from nbcalib.errors import InputError
from nbcalib.io.calib_json import CalibFile, write_calib_json
from nbcalib.io.camera_file import load_camera, save_camera

DATA = Path(__file__).parent / "data"

# one camera of every model, with distinct fx/fy/cx/cy so that a transposed K would show
CAMERAS = {
    "pinhole": create_camera("pinhole", [500.5, 501.25, 319.75, 240.125], [], 640, 480),
    "plumb_bob": create_camera(
        "plumb_bob", [500.5, 501.25, 319.75, 240.125], [-0.1, 0.01, 1e-3, -2e-3, 1e-4], 640, 480
    ),
    "rational_polynomial": create_camera(
        "rational_polynomial",
        [700.1, 700.2, 640.3, 360.4],
        [0.5, -0.02, 1e-4, 2e-4, 3e-3, 0.8, 0.01, 1e-3],
        1280,
        720,
    ),
    "fisheye": create_camera(
        "fisheye", [300.0, 301.0, 512.5, 384.5], [0.02, -0.01, 3e-3, -1e-4], 1024, 768
    ),
    "atan": create_camera("atan", [400.0, 401.0, 320.0, 240.0], [0.9], 640, 480),
    "omnidir": create_camera(
        "omnidir", [600.0, 601.0, 512.0, 511.0, 0.9], [-0.2, 0.05, 1e-3, 2e-3], 1024, 1024
    ),
    "equirectangular": create_camera("equirectangular", [2048, 1024], [], 2048, 1024),
}


def test_every_model_has_a_test_camera():
    assert set(CAMERAS) == set(CAMERA_MODELS)


def test_ros_camera_info_yaml():
    cam = load_camera(DATA / "camera_info_ros.yaml")
    assert cam.model == "plumb_bob"
    assert (cam.width, cam.height) == (1280, 720)
    np.testing.assert_array_equal(cam.intrinsics, [912.34, 915.67, 641.27, 362.89])
    np.testing.assert_array_equal(
        cam.distortion_coeffs, [-0.312, 0.0981, 0.00121, -0.00077, -0.0123]
    )


def test_ros_camera_info_equidistant_is_fisheye(tmp_path):
    text = (DATA / "camera_info_ros.yaml").read_text()
    text = text.replace("distortion_model: plumb_bob", "distortion_model: equidistant")
    text = text.replace(
        "cols: 5\n  data: [-0.312, 0.0981, 0.00121, -0.00077, -0.0123]",
        "cols: 4\n  data: [0.01, -0.002, 0.0003, -0.00004]",
    )
    path = tmp_path / "fisheye_info.yaml"
    path.write_text(text)
    cam = load_camera(path)
    assert cam.model == "fisheye"
    np.testing.assert_array_equal(cam.distortion_coeffs, [0.01, -0.002, 0.0003, -0.00004])


def test_ros2_camera_info_message_dump(tmp_path):
    # `ros2 topic echo --once /camera_info` output (lower-case k, d)
    path = tmp_path / "msg.yaml"
    path.write_text(
        "header:\n  frame_id: cam\nheight: 480\nwidth: 640\ndistortion_model: plumb_bob\n"
        "d: [0.1, -0.2, 0.0, 0.0, 0.0]\nk: [500.0, 0.0, 320.5, 0.0, 502.0, 240.5, 0.0, 0.0, 1.0]\n"
        "r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]\n"
    )
    cam = load_camera(path)
    assert (cam.model, cam.width, cam.height) == ("plumb_bob", 640, 480)
    np.testing.assert_array_equal(cam.intrinsics, [500.0, 502.0, 320.5, 240.5])


def test_opencv_filestorage_yaml():
    cam = load_camera(DATA / "camera_opencv.yaml")
    storage = cv2.FileStorage(str(DATA / "camera_opencv.yaml"), cv2.FILE_STORAGE_READ)
    K = storage.getNode("camera_matrix").mat()
    D = storage.getNode("distortion_coefficients").mat().ravel()
    assert cam.model == "plumb_bob"
    assert (cam.width, cam.height) == (1920, 1080)
    np.testing.assert_array_equal(cam.K, K)
    np.testing.assert_array_equal(cam.distortion_coeffs, D)


def test_opencv_fisheye_and_plain_yaml_with_K_D(tmp_path):
    path = tmp_path / "fisheye.yaml"
    path.write_text(
        "%YAML:1.0\n---\nimage_width: 800\nimage_height: 600\ndistortion_model: fisheye\n"
        "K: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
        "   data: [ 280., 0., 400.5, 0., 281., 300.5, 0., 0., 1. ]\n"
        "D: [ 0.01, 0.02, -0.003, 0.0004 ]\n"
    )
    cam = load_camera(path)
    assert (cam.model, cam.width, cam.height) == ("fisheye", 800, 600)
    np.testing.assert_array_equal(cam.intrinsics, [280.0, 281.0, 400.5, 300.5])
    np.testing.assert_array_equal(cam.distortion_coeffs, [0.01, 0.02, -0.003, 0.0004])

    plain = tmp_path / "plain.json"
    plain.write_text(json.dumps({"K": [[280.0, 0, 400.5], [0, 281.0, 300.5], [0, 0, 1]], "D": []}))
    cam = load_camera(plain, width=800, height=600)
    assert cam.model == "pinhole"
    np.testing.assert_array_equal(cam.intrinsics, [280.0, 281.0, 400.5, 300.5])


def test_plain_json_model_key_selects_fisheye(tmp_path):
    """The shared real data's calib_normalized.json names the model under ``model``."""
    path = tmp_path / "calib_normalized.json"
    K = [[959.554, 0, 940.789], [0, 960.194, 670.737], [0, 0, 1]]
    doc = {"K": K, "dist": [-0.0978, 0.1414, -0.1484, 0.0559], "width": 1920, "height": 1208}
    path.write_text(json.dumps({**doc, "model": "fisheye"}))
    cam = load_camera(path)
    assert (cam.model, cam.width, cam.height) == ("fisheye", 1920, 1208)
    np.testing.assert_array_equal(cam.distortion_coeffs, [-0.0978, 0.1414, -0.1484, 0.0559])
    path.write_text(json.dumps({**doc, "model": "plumb_bob"}))
    assert load_camera(path).model == "plumb_bob"


def test_nbcalib_yaml_fixture():
    cam = load_camera(DATA / "camera_nbcalib.yaml")
    assert cam == create_camera(
        "fisheye", [380.5, 381.25, 511.75, 383.5], [0.021, -0.0043, 0.0012, -0.0002], 1024, 768
    )


@pytest.mark.parametrize("model", CAMERA_MODELS)
@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_save_load_round_trip_is_exact(tmp_path, model, suffix):
    cam = CAMERAS[model]
    path = tmp_path / f"camera{suffix}"
    save_camera(path, cam)
    loaded = load_camera(path)
    assert loaded == cam  # exact: model, size, intrinsics and distortion bit for bit
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_saved_yaml_has_header_and_reads_as_plain_yaml(tmp_path):
    import yaml

    path = tmp_path / "camera.yaml"
    save_camera(path, CAMERAS["omnidir"])
    text = path.read_text()
    assert text.startswith("# nbcalib camera")
    assert "x right, y down, z forward" in text
    assert yaml.safe_load(text) == CAMERAS["omnidir"].to_dict()


def test_calib_json_with_nbcalib_size(tmp_path):
    calib = CalibFile(meta={"bag_names": ["x"]})
    calib.set_camera(CAMERAS["pinhole"])
    write_calib_json(tmp_path / "calib.json", calib)
    assert load_camera(tmp_path / "calib.json") == CAMERAS["pinhole"]


def test_reference_calib_json_needs_size(tmp_path):
    path = tmp_path / "calib.json"
    shutil.copy(DATA / "reference_calib.json", path)
    with pytest.raises(InputError, match="image size"):
        load_camera(path)
    cam = load_camera(path, width=2448, height=2048)
    assert (cam.model, cam.width, cam.height) == ("plumb_bob", 2448, 2048)
    np.testing.assert_array_equal(
        cam.intrinsics, [1452.711762456289, 1455.877531619469, 1265.25895179213, 1045.818593664107]
    )
    # the camera image of the work directory gives the size when present
    image = np.zeros((2048, 2448), np.uint8)
    assert cv2.imwrite(str(tmp_path / "rosbag2_2023_03_09-13_42_46.png"), image)
    assert (load_camera(path).width, load_camera(path).height) == (2448, 2048)


def test_size_arguments(tmp_path):
    assert load_camera(DATA / "camera_info_ros.yaml", width=1280, height=720).width == 1280
    with pytest.raises(InputError, match="1280x720"):
        load_camera(DATA / "camera_info_ros.yaml", width=640, height=480)
    path = tmp_path / "nosize.yaml"
    path.write_text("K: [500, 0, 320, 0, 500, 240, 0, 0, 1]\nD: [0, 0, 0, 0]\n")
    with pytest.raises(InputError, match="image size"):
        load_camera(path)
    # ROS writes 0 x 0 when it does not know the size
    zero = tmp_path / "zero.yaml"
    zero.write_text(
        (DATA / "camera_info_ros.yaml").read_text().replace(": 1280", ": 0").replace(": 720", ": 0")
    )
    with pytest.raises(InputError, match="image size"):
        load_camera(zero)
    assert load_camera(zero, width=1280, height=720).width == 1280


BAD_FILES = {
    "invalid_yaml.yaml": ("camera_model: [plumb_bob\nintrinsics: 3\n", "invalid YAML at line"),
    "not_a_camera.yaml": ("foo: 1\nbar: 2\n", "not a camera file"),
    "a_list.yaml": ("- 1\n- 2\n", "not a camera file"),
    "wrong_count.yaml": (
        "camera_model: plumb_bob\nwidth: 640\nheight: 480\nintrinsics: [1, 2, 3]\n",
        "takes 4 intrinsics",
    ),
    "nan.yaml": (
        "camera_model: pinhole\nwidth: 640\nheight: 480\nintrinsics: [.nan, 500, 320, 240]\n",
        "non-finite",
    ),
    "text_intrinsics.yaml": (
        "camera_model: pinhole\nwidth: 640\nheight: 480\nintrinsics: fx\n",
        "intrinsics must be a list of numbers",
    ),
    "unknown_model.yaml": (
        "camera_model: kinect\nwidth: 640\nheight: 480\nintrinsics: [1, 1, 1, 1]\n",
        "unknown camera model",
    ),
    "bad_K.yaml": (
        "image_width: 640\nimage_height: 480\ndistortion_model: plumb_bob\n"
        "camera_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0]}\n",
        "must have 9 numbers",
    ),
    "half_size.yaml": (
        "camera_model: pinhole\nwidth: 640.5\nheight: 480\nintrinsics: [500, 500, 320, 240]\n",
        "whole numbers",
    ),
    "broken_opencv.yaml": ("%YAML:1.0\n---\nK: [1, 2\n", "OpenCV FileStorage"),
    "bad.json": ('{"camera_model": "pinhole",', "invalid JSON"),
    "calib_bad_pose.json": (
        '{"camera": {"camera_model": "pinhole", "intrinsics": [1, 1, 0, 0], '
        '"distortion_coeffs": []}, "results": {"T_lidar_camera": [0, 0, 0, 1]}}',
        "7 numbers",
    ),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
def test_bad_files_give_input_error_naming_the_file(tmp_path, name):
    text, message = BAD_FILES[name]
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError, match=message) as info:
        load_camera(path)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)


def test_missing_and_directory(tmp_path):
    with pytest.raises(InputError, match="not found") as info:
        load_camera(tmp_path / "nope.yaml")
    assert "nope.yaml" in str(info.value)
    with pytest.raises(InputError, match="directory"):
        load_camera(tmp_path)


def test_real_data_normalised_calibration_camera(real_data):
    path = real_data / "pjlab" / "auto_calib" / "calib_normalized.json"
    raw = json.loads(path.read_text())
    cam = load_camera(path)
    assert (cam.width, cam.height) == (raw["width"], raw["height"])
    np.testing.assert_array_equal(cam.K, raw["K"])
    assert cam.model == "plumb_bob"  # the distortion under "dist" is not dropped
    np.testing.assert_array_equal(cam.distortion_coeffs, raw["dist"])
