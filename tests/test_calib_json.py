"""calib.json: the reference toolbox's schema, our additions, the pose convention, atomic writes."""

from __future__ import annotations

import json
import os
import shutil
import stat
from pathlib import Path

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from tolerances import TOL

from nbcalib.camera import create_camera
from nbcalib.errors import InputError
from nbcalib.io import calib_json
from nbcalib.io.calib_json import (
    AUTO_STAGE,
    FINAL_STAGE,
    MANUAL_STAGE,
    STAGES,
    CalibFile,
    read_calib_json,
    write_calib_json,
)
from nbcalib.io.job_record import CameraEntry

DATA = Path(__file__).parent / "data"
REFERENCE = DATA / "reference_calib.json"


def T_lidar_camera_of(values) -> np.ndarray:
    """Independent decoding of [x, y, z, qx, qy, qz, qw] (scipy, scalar-last)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(values[3:]).as_matrix()
    T[:3, 3] = values[:3]
    return T


def random_T_camera_lidar(rng) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng.integers(1 << 31)).as_matrix()
    T[:3, 3] = rng.normal(scale=0.5, size=3)
    return T


def assert_tree_close(a, b, path="root"):
    """Same nested structure and keys; floats equal to 1e-12."""
    assert type(a) is type(b) or {type(a), type(b)} <= {int, float}, path
    if isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for key in a:
            assert_tree_close(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_tree_close(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert abs(a - b) <= 1e-12 * max(1.0, abs(a)), path
    else:
        assert a == b, path


# --------------------------------------------------------------------------- reference file
def test_reference_file_loads():
    calib = read_calib_json(REFERENCE)
    raw = json.loads(REFERENCE.read_text())
    assert calib.camera == raw["camera"]
    assert calib.meta["bag_names"] == ["rosbag2_2023_03_09-13_42_46", "rosbag2_2023_03_09-13_44_10"]
    assert calib.bag_names == calib.meta["bag_names"]
    assert calib.meta["intensity_channel"] == "intensity"
    assert set(calib.results) == set(STAGES)
    assert calib.extra == {} and calib.record.to_dict() == {}
    for stage in STAGES:
        assert calib.has_result(stage)
        T_camera_lidar = calib.get_T_camera_lidar(stage)
        expected = np.linalg.inv(T_lidar_camera_of(raw["results"][stage]))
        np.testing.assert_allclose(T_camera_lidar, expected, **TOL["transform"])
    assert calib.latest_stage() == FINAL_STAGE
    assert calib.latest_initial_stage() == MANUAL_STAGE  # no times: manual first, as calibrate
    cam = calib.camera_model(2448, 2048)
    assert cam.model == "plumb_bob" and (cam.width, cam.height) == (2448, 2048)
    np.testing.assert_array_equal(cam.intrinsics, raw["camera"]["intrinsics"])
    np.testing.assert_array_equal(cam.distortion_coeffs, raw["camera"]["distortion_coeffs"])


def test_reference_file_is_rewritten_byte_for_byte(tmp_path):
    # the fixture is in nlohmann dump(2) form: sorted keys, indent 2, final newline
    write_calib_json(tmp_path / "calib.json", read_calib_json(REFERENCE))
    assert (tmp_path / "calib.json").read_bytes() == REFERENCE.read_bytes()


def test_camera_lidar_convention_on_a_known_pose():
    # camera looking along the LiDAR's x axis, 0.1 m forward of it
    R_lidar_camera = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    T_lidar_camera = np.eye(4)
    T_lidar_camera[:3, :3] = R_lidar_camera
    T_lidar_camera[:3, 3] = [0.1, 0.0, 0.0]
    T_camera_lidar = np.linalg.inv(T_lidar_camera)
    calib = CalibFile()
    calib.set_T_camera_lidar(FINAL_STAGE, T_camera_lidar)
    values = calib.results[FINAL_STAGE]
    np.testing.assert_allclose(values[:3], [0.1, 0.0, 0.0], **TOL["transform"])
    q = np.array(values[3:])
    q_expected = Rotation.from_matrix(R_lidar_camera).as_quat()
    assert min(np.abs(q - q_expected).max(), np.abs(q + q_expected).max()) < 1e-12
    # a LiDAR point 5 m ahead is 4.9 m in front of the camera (camera z)
    p_camera = calib.get_T_camera_lidar(FINAL_STAGE) @ [5.0, 0.0, 0.0, 1.0]
    np.testing.assert_allclose(p_camera[:3], [0.0, 0.0, 4.9], **TOL["transform"])


# --------------------------------------------------------------------------- our files
def test_written_file_has_the_schema_the_reference_reads(tmp_path, rng):
    camera = create_camera("pinhole", [500.0, 501.0, 320.0, 240.0], [], 640, 480)
    calib = CalibFile(
        meta={
            "data_path": "bags",
            "camera_info_topic": "/camera_info",
            "image_topic": "/image",
            "points_topic": "/points",
            "intensity_channel": "intensity",
            "bag_names": ["a", "b"],
        }
    )
    calib.set_camera(camera)
    poses = {stage: random_T_camera_lidar(rng) for stage in STAGES}
    for stage, T in poses.items():
        calib.set_T_camera_lidar(stage, T)
    path = tmp_path / "calib.json"
    write_calib_json(path, calib)

    text = path.read_text(encoding="utf-8")
    raw = json.loads(text)
    assert text == json.dumps(raw, indent=2, sort_keys=True) + "\n"  # nlohmann dump(2) layout
    # what the reference's tools read, with the C++ types they read it as
    assert isinstance(raw["camera"]["camera_model"], str)
    assert raw["camera"]["camera_model"] == "plumb_bob"  # the reference does not know pinhole
    assert raw["camera"]["distortion_coeffs"] == [0.0] * 5
    assert all(type(x) is float for x in raw["camera"]["distortion_coeffs"])
    assert all(type(x) is float for x in raw["camera"]["intrinsics"])
    for key in calib_json.META_KEYS[:-1]:
        assert isinstance(raw["meta"][key], str)
    assert raw["meta"]["bag_names"] == ["a", "b"]
    for stage in STAGES:
        values = raw["results"][stage]
        assert len(values) == 7 and all(type(x) is float for x in values)
        assert abs(np.linalg.norm(values[3:]) - 1.0) < 1e-12
        np.testing.assert_allclose(
            T_lidar_camera_of(values), np.linalg.inv(poses[stage]), **TOL["transform"]
        )
    assert set(raw) == {"camera", "meta", "results", "nbcalib"}
    assert set(raw["nbcalib"]["result_times"]) == set(STAGES)
    assert raw["nbcalib"]["camera"] == {"camera_model": "pinhole", "width": 640, "height": 480}

    back = read_calib_json(path)
    assert back.camera_model() == camera  # pinhole again, size from the nbcalib section
    for stage in STAGES:
        np.testing.assert_allclose(back.get_T_camera_lidar(stage), poses[stage], **TOL["transform"])


def test_round_trip_preserves_unknown_keys_and_values(tmp_path, rng):
    values = [float(x) for x in rng.normal(size=7)]
    data = {
        "camera": {
            "camera_model": "omnidir",
            "intrinsics": [float(x) for x in rng.uniform(100, 1000, 5)],
            "distortion_coeffs": [float(x) for x in rng.normal(scale=0.1, size=4)],
            "comment": "from kalibr",
        },
        "meta": {"bag_names": ["x"], "data_path": "ü/ß", "custom": {"n": 3, "v": [0.1, 1e-300]}},
        "results": {FINAL_STAGE: values, "T_imu_camera": [1.0, 2.0], "note": None},
        "nbcalib": {"quality": {"nid": float(rng.uniform()), "ok": True}},
        "other_tool": {"a": [1, 2, 3], "b": "text", "c": 1.0000000000000002},
        "version": 7,
    }
    path = tmp_path / "calib.json"
    path.write_text(json.dumps(data))
    calib = read_calib_json(path)
    assert calib.extra == {"other_tool": data["other_tool"], "version": 7}
    write_calib_json(path, calib)
    assert_tree_close(json.loads(path.read_text(encoding="utf-8")), data)
    assert_tree_close(read_calib_json(path).to_dict(), data)


def test_numpy_values_in_our_section_are_written(tmp_path):
    calib = read_calib_json(REFERENCE)
    calib.record.other["residuals"] = np.arange(3.0)
    calib.record.other["count"] = np.int64(5)
    write_calib_json(tmp_path / "calib.json", calib)
    back = read_calib_json(tmp_path / "calib.json")
    assert back.record.to_dict() == {"residuals": [0.0, 1.0, 2.0], "count": 5}


def test_quaternion_is_normalised(tmp_path):
    raw = json.loads(REFERENCE.read_text())
    unit = raw["results"][FINAL_STAGE]
    raw["results"][FINAL_STAGE] = unit[:3] + [2.5 * q for q in unit[3:]]
    path = tmp_path / "calib.json"
    path.write_text(json.dumps(raw))
    calib = read_calib_json(path)
    T = calib.get_T_camera_lidar(FINAL_STAGE)
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), **TOL["transform"])
    np.testing.assert_allclose(T, np.linalg.inv(T_lidar_camera_of(unit)), **TOL["transform"])
    calib.set_T_camera_lidar(FINAL_STAGE, T)
    assert abs(np.linalg.norm(calib.results[FINAL_STAGE][3:]) - 1.0) < 1e-12


def test_set_rejects_bad_matrices_and_stages():
    calib = CalibFile()
    with pytest.raises(ValueError):
        calib.set_T_camera_lidar(FINAL_STAGE, np.eye(3))
    with pytest.raises(ValueError):
        calib.set_T_camera_lidar(FINAL_STAGE, np.full((4, 4), np.nan))
    with pytest.raises(ValueError, match="stage"):
        calib.set_T_camera_lidar("T_camera_lidar", np.eye(4))
    with pytest.raises(InputError, match="no result"):
        calib.get_T_camera_lidar(AUTO_STAGE)


def test_write_without_camera_is_a_programming_error(tmp_path):
    with pytest.raises(ValueError, match="camera"):
        write_calib_json(tmp_path / "calib.json", CalibFile())
    calib = read_calib_json(REFERENCE)
    calib.record.other["bad"] = float("nan")
    with pytest.raises(ValueError):
        write_calib_json(tmp_path / "calib.json", calib)
    assert list(tmp_path.iterdir()) == []


# --------------------------------------------------------------------------- latest stage
def _calib_with(stages, times=None) -> CalibFile:
    calib = read_calib_json(REFERENCE)
    calib.results = {stage: calib.results[stage] for stage in stages}
    if times is not None:
        calib.record.result_times = times
    return calib


@pytest.mark.parametrize(
    ("stages", "times", "expected"),
    [
        ((), None, None),
        ((AUTO_STAGE,), None, AUTO_STAGE),
        ((MANUAL_STAGE,), None, MANUAL_STAGE),
        ((MANUAL_STAGE, AUTO_STAGE), None, MANUAL_STAGE),
        (
            (MANUAL_STAGE, AUTO_STAGE),
            {MANUAL_STAGE: "2025-01-01T10:00:00+00:00", AUTO_STAGE: "2025-01-01T10:00:01+00:00"},
            AUTO_STAGE,
        ),
        (
            (MANUAL_STAGE, AUTO_STAGE),
            {MANUAL_STAGE: "2025-01-01T12:00:00+02:00", AUTO_STAGE: "2025-01-01T10:30:00+00:00"},
            AUTO_STAGE,  # time zones are compared correctly: 10:00 UTC < 10:30 UTC
        ),
        (
            (MANUAL_STAGE, AUTO_STAGE),
            {MANUAL_STAGE: "2025-01-02T00:00:00+00:00", AUTO_STAGE: "2025-01-01T00:00:00+00:00"},
            MANUAL_STAGE,
        ),
        # only one time known (the other written by the reference): reference order
        ((MANUAL_STAGE, AUTO_STAGE), {AUTO_STAGE: "2025-01-01T00:00:00+00:00"}, MANUAL_STAGE),
        ((MANUAL_STAGE, AUTO_STAGE), {AUTO_STAGE: "garbage", MANUAL_STAGE: 3}, MANUAL_STAGE),
        ((FINAL_STAGE, AUTO_STAGE), None, FINAL_STAGE),
    ],
)
def test_latest_stage(stages, times, expected):
    assert _calib_with(stages, times).latest_stage() == expected


def test_latest_initial_guess_follows_write_order(tmp_path):
    calib = _calib_with(())
    calib.set_T_camera_lidar(AUTO_STAGE, np.eye(4))
    calib.set_T_camera_lidar(MANUAL_STAGE, np.eye(4))
    calib.set_T_camera_lidar(AUTO_STAGE, np.eye(4))  # rewritten last
    write_calib_json(tmp_path / "calib.json", calib)
    back = read_calib_json(tmp_path / "calib.json")
    assert back.result_time(AUTO_STAGE) > back.result_time(MANUAL_STAGE)
    assert back.latest_stage() == AUTO_STAGE
    back.set_T_camera_lidar(MANUAL_STAGE, np.eye(4))
    assert back.latest_stage() == MANUAL_STAGE
    back.set_T_camera_lidar(FINAL_STAGE, np.eye(4))
    assert back.latest_stage() == FINAL_STAGE


def test_time_of_a_result_rewritten_by_the_reference_is_unknown(tmp_path):
    calib = _calib_with(())
    calib.set_T_camera_lidar(MANUAL_STAGE, np.eye(4))
    calib.set_T_camera_lidar(AUTO_STAGE, np.eye(4))
    path = tmp_path / "calib.json"
    write_calib_json(path, calib)
    assert read_calib_json(path).latest_stage() == AUTO_STAGE
    # the reference's initial_guess_manual rewrites only results.init_T_lidar_camera
    raw = json.loads(path.read_text())
    raw["results"][MANUAL_STAGE] = [0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    path.write_text(json.dumps(raw, indent=2, sort_keys=True))
    back = read_calib_json(path)
    assert back.result_time(MANUAL_STAGE) is None
    assert back.result_time(AUTO_STAGE) is not None
    assert back.latest_stage() == MANUAL_STAGE  # unknown order: the reference's preference


def test_write_order_decides_on_a_stopped_clock(monkeypatch):
    frozen = calib_json.datetime(2025, 1, 1, tzinfo=calib_json.timezone.utc)

    class StoppedClock(calib_json.datetime):
        @classmethod
        def now(cls, tz=None):
            return frozen

    monkeypatch.setattr(calib_json, "datetime", StoppedClock)
    calib = _calib_with(())
    for stage in (MANUAL_STAGE, AUTO_STAGE, MANUAL_STAGE):
        calib.set_T_camera_lidar(stage, np.eye(4))
        assert calib.latest_stage() == stage
    assert calib.result_time(MANUAL_STAGE) == frozen + calib_json.timedelta(microseconds=2)


# --------------------------------------------------------------------------- camera size
def test_camera_size_sources(tmp_path):
    path = tmp_path / "calib.json"
    shutil.copy(REFERENCE, path)
    calib = read_calib_json(path)
    with pytest.raises(InputError, match="image size is unknown") as info:
        calib.camera_model()
    assert str(path) in str(info.value)
    assert cv2.imwrite(
        str(tmp_path / "rosbag2_2023_03_09-13_42_46.png"), np.zeros((48, 64), np.uint8)
    )
    assert (calib.camera_model().width, calib.camera_model().height) == (64, 48)
    with pytest.raises(InputError, match="64x48 images, not 640x480"):
        calib.camera_model(640, 480)
    calib.record.camera = CameraEntry(width=2448, height=2048)  # recorded size wins over the image
    assert calib.camera_model().width == 2448


def test_equirectangular_size_from_intrinsics():
    calib = CalibFile(
        camera={
            "camera_model": "equirectangular",
            "intrinsics": [1920.0, 960.0],
            "distortion_coeffs": [],
        }
    )
    cam = calib.camera_model()
    assert (cam.model, cam.width, cam.height) == ("equirectangular", 1920, 960)


@pytest.mark.parametrize(
    ("model", "given", "expected"),
    [
        ("plumb_bob", [0.1, -0.2, 0.001, 0.002], [0.1, -0.2, 0.001, 0.002, 0.0]),  # padded
        ("fisheye", [0.1, 0.2, 0.3, 0.4, 0.0, 0.0], [0.1, 0.2, 0.3, 0.4]),  # zeros dropped
        ("equidistant", [0.1], [0.1, 0.0, 0.0, 0.0]),
        ("pinhole", [0.0, 0.0, 0.0, 0.0, 0.0], []),
    ],
)
def test_distortion_fitted_like_the_reference(model, given, expected):
    calib = CalibFile(
        camera={
            "camera_model": model,
            "intrinsics": [500.0, 500.0, 320.0, 240.0],
            "distortion_coeffs": given,
        }
    )
    np.testing.assert_array_equal(calib.camera_model(640, 480).distortion_coeffs, expected)


def test_extra_nonzero_distortion_is_an_error():
    calib = CalibFile(
        camera={
            "camera_model": "plumb_bob",
            "intrinsics": [500.0, 500.0, 320.0, 240.0],
            "distortion_coeffs": [0.1, 0.0, 0.0, 0.0, 0.0, 0.3],
        }
    )
    with pytest.raises(InputError, match="takes 5 distortion coefficients, got 6"):
        calib.camera_model(640, 480)


def test_bad_camera_values_are_input_errors():
    calib = CalibFile(
        camera={
            "camera_model": "plumb_bob",
            "intrinsics": [-1.0, 500.0, 320.0, 240.0],
            "distortion_coeffs": [],
        }
    )
    with pytest.raises(InputError, match="focal"):
        calib.camera_model(640, 480)


# --------------------------------------------------------------------------- atomic writes
def test_atomic_write_keeps_old_file_on_crash(tmp_path, monkeypatch):
    path = tmp_path / "calib.json"
    shutil.copy(REFERENCE, path)
    before = path.read_bytes()
    calib = read_calib_json(path)
    calib.set_T_camera_lidar(FINAL_STAGE, np.eye(4))

    def crash(*args, **kwargs):
        raise OSError("disk on fire")

    monkeypatch.setattr(calib_json.os, "replace", crash)
    with pytest.raises(OSError, match="disk on fire"):
        write_calib_json(path, calib)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["calib.json"]  # temporary file removed
    monkeypatch.undo()
    write_calib_json(path, calib)
    assert read_calib_json(path).results[FINAL_STAGE] == calib.results[FINAL_STAGE]
    assert [p.name for p in tmp_path.iterdir()] == ["calib.json"]


def test_write_keeps_permissions(tmp_path):
    path = tmp_path / "calib.json"
    shutil.copy(REFERENCE, path)
    os.chmod(path, 0o640)
    write_calib_json(path, read_calib_json(path))
    assert stat.S_IMODE(path.stat().st_mode) == 0o640


# --------------------------------------------------------------------------- bad files
def _reference_with(**changes) -> str:
    raw = json.loads(REFERENCE.read_text())
    for dotted, value in changes.items():
        *parents, key = dotted.split("__")
        node = raw
        for parent in parents:
            node = node[parent]
        if value is _DELETE:
            del node[key]
        else:
            node[key] = value
    return json.dumps(raw)


_DELETE = object()

BAD = {
    "empty": ("", "invalid JSON at line 1"),
    "truncated": (REFERENCE.read_text()[:200], "invalid JSON at line"),
    "nan": (REFERENCE.read_text().replace("0.0512", "NaN"), "non-finite number NaN"),
    "infinity": (
        REFERENCE.read_text().replace("0.0512", "-Infinity"),
        "non-finite number -Infinity",
    ),
    "overflow": (REFERENCE.read_text().replace("0.0512", "1e999"), "non-finite number 1e999"),
    "top_level_list": ("[1, 2]", "JSON object at the top level"),
    "no_camera": (_reference_with(camera=_DELETE), "no 'camera' entry"),
    "camera_not_object": (_reference_with(camera=[1]), "'camera' must be a JSON object"),
    "no_intrinsics": (_reference_with(camera__intrinsics=_DELETE), "camera lacks intrinsics"),
    "no_model_no_coeffs": (
        _reference_with(camera__camera_model=_DELETE, camera__distortion_coeffs=_DELETE),
        "camera lacks camera_model, distortion_coeffs",
    ),
    "model_not_str": (_reference_with(camera__camera_model=3), "camera_model must be"),
    "intrinsics_text": (
        _reference_with(camera__intrinsics=["500"] * 4),
        "intrinsics must be a list",
    ),
    "intrinsics_bool": (
        _reference_with(camera__intrinsics=[True] * 4),
        "intrinsics must be a list",
    ),
    "meta_list": (_reference_with(meta=[]), "'meta' must be a JSON object"),
    "results_list": (_reference_with(results=[1]), "'results' must be a JSON object"),
    "pose_6": (
        _reference_with(results__T_lidar_camera=[0.0] * 6),
        "results.T_lidar_camera must be 7",
    ),
    "pose_8": (
        _reference_with(results__init_T_lidar_camera=[0.0] * 8),
        "init_T_lidar_camera must be 7",
    ),
    "pose_text": (_reference_with(results__init_T_lidar_camera_auto="0 0 0 0 0 0 1"), "must be 7"),
    "pose_null": (
        _reference_with(results__T_lidar_camera=[0, 0, 0, 0, 0, 0, None]),
        "must be a list of numbers",
    ),
    "zero_quaternion": (
        _reference_with(results__T_lidar_camera=[1, 2, 3, 0, 0, 0, 0]),
        "zero quaternion",
    ),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_files_give_input_error_naming_the_file(tmp_path, name):
    text, message = BAD[name]
    path = tmp_path / f"{name}.json"
    path.write_text(text)
    with pytest.raises(InputError, match=message) as info:
        read_calib_json(path)
    assert str(info.value).startswith(f"{path}: ")
    assert "\n" not in str(info.value)


def test_missing_directory_and_binary_files(tmp_path):
    with pytest.raises(InputError, match="file not found"):
        read_calib_json(tmp_path / "calib.json")
    with pytest.raises(InputError, match="directory"):
        read_calib_json(tmp_path)
    (tmp_path / "binary.json").write_bytes(b"\xff\xfe\x00\x81")
    with pytest.raises(InputError, match="UTF-8"):
        read_calib_json(tmp_path / "binary.json")


def test_bag_names_must_be_strings():
    calib = read_calib_json(REFERENCE)
    calib.meta["bag_names"] = "one"
    with pytest.raises(InputError, match="bag_names"):
        calib.bag_names  # noqa: B018
