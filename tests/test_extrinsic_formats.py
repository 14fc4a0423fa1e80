"""Exports of a result (tf2, ROS 2 launch, URDF, OpenCV YAML): each read back to the same pose."""

from __future__ import annotations

import ast
import math
import shlex
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
from numpy.testing import assert_allclose
from scipy.spatial.transform import Rotation
from tolerances import TOL

from nbcalib.camera import example_camera
from nbcalib.cli import main
from nbcalib.errors import InputError
from nbcalib.io.calib_json import CalibFile, write_calib_json
from nbcalib.io.camera_file import load_camera
from nbcalib.io.extrinsic_formats import (
    FILE_NAMES,
    export_result,
    load_result,
    matrix_from_rpy,
    opencv_yaml_text,
    ros2_launch_text,
    rpy_from_matrix,
    tf2_arguments,
    tf2_text,
    urdf_text,
)
from nbcalib.transforms import (
    invert_T,
    make_T,
    matrix_to_quat_xyzw,
    pose_from_xyz_quat,
    quat_xyzw_to_matrix,
    random_pose,
    rotation_angle_deg,
    transform_points,
)

# A camera looking along the LiDAR's x axis, as on most rigs: pitch of the optical frame in the
# LiDAR frame is close to 90 degrees, the URDF rpy gimbal lock.
T_LIDAR_CAMERA_RIG = pose_from_xyz_quat(
    [0.0232, -0.0493, -0.0010, 0.00276, 0.71217, 0.00384, 0.70199]
)


def _assert_same_pose(T_a, T_b):
    assert_allclose(T_a[:3, 3], T_b[:3, 3], **TOL["transform"])
    assert rotation_angle_deg(T_a[:3, :3] @ T_b[:3, :3].T) < 1e-9


def _pose_from_ros2_args(args):
    values = dict(zip(args[0::2], args[1::2]))
    xyzq = [float(values[f"--{k}"]) for k in ("x", "y", "z", "qx", "qy", "qz", "qw")]
    return pose_from_xyz_quat(xyzq), values["--frame-id"], values["--child-frame-id"]


def _pose_from_ros1_args(args):
    assert len(args) == 9
    return pose_from_xyz_quat([float(a) for a in args[:7]]), args[7], args[8]


def _workdir(tmp_path, camera, results):
    """A work directory whose calib.json holds ``results`` {stage: T_camera_lidar}."""
    calib = CalibFile()
    calib.set_camera(camera)
    calib.meta = {"bag_names": ["pair0"]}
    for stage, T_camera_lidar in results.items():
        calib.set_T_camera_lidar(stage, T_camera_lidar)
    workdir = tmp_path / "work"
    workdir.mkdir()
    write_calib_json(workdir / "calib.json", calib)
    return workdir


# ---------------------------------------------------------------------- URDF rpy
def test_rpy_matches_scipy_fixed_axis_xyz(rng):
    rpy = np.column_stack(
        [rng.uniform(-math.pi, math.pi, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)]
    )
    for angles in rpy:
        # scipy "xyz" (lower case) = extrinsic (fixed-axis) x, then y, then z: Rz Ry Rx
        expected = Rotation.from_euler("xyz", angles).as_matrix()
        assert_allclose(matrix_from_rpy(angles), expected, **TOL["transform"])
        assert_allclose(rpy_from_matrix(expected), angles, **TOL["transform"])


def test_rpy_round_trip_random_rotations(rng):
    for _ in range(200):
        R = random_pose(rng)[:3, :3]
        assert_allclose(matrix_from_rpy(rpy_from_matrix(R)), R, **TOL["transform"])


@pytest.mark.parametrize("sign", [1.0, -1.0])
@pytest.mark.parametrize("gap", [0.0, 1e-14, 1e-12, 1e-10, 1e-9, 1e-8, 1e-7, 1e-6, 1e-4])
def test_rpy_round_trip_near_gimbal_lock(rng, sign, gap):
    """Camera optical frames in a LiDAR frame sit near pitch = 90 degrees: the hard case."""
    for _ in range(50):
        roll, yaw = rng.uniform(-math.pi, math.pi, 2)
        R_exact = matrix_from_rpy([roll, sign * (math.pi / 2 - gap), yaw])
        # through a quaternion, as from calib.json: entries carry ~1e-16 absolute noise, which
        # makes roll alone ill-conditioned near the lock (a naive atan2 split loses ~1e-7)
        R = quat_xyzw_to_matrix(matrix_to_quat_xyzw(R_exact))
        rpy = rpy_from_matrix(R)
        assert abs(rpy[1]) <= math.pi / 2
        assert_allclose(matrix_from_rpy(rpy), R, **TOL["transform"])
    assert rpy_from_matrix(matrix_from_rpy([0.3, sign * math.pi / 2, -1.1]))[0] == 0.0


def test_rpy_rejects_bad_input():
    with pytest.raises(ValueError):
        rpy_from_matrix(np.eye(4))
    with pytest.raises(ValueError):
        rpy_from_matrix(np.full((3, 3), np.nan))


def test_urdf_round_trip(rng):
    for T in [T_LIDAR_CAMERA_RIG, *random_pose(rng, size=20)]:
        text = urdf_text(T, parent_frame="velodyne", child_frame="camera_optical_frame")
        root = ET.fromstring(text)
        joint = root.find("joint")
        assert joint.get("type") == "fixed"
        assert joint.find("parent").get("link") == "velodyne"
        assert joint.find("child").get("link") == "camera_optical_frame"
        origin = joint.find("origin")
        xyz = [float(v) for v in origin.get("xyz").split()]
        rpy = [float(v) for v in origin.get("rpy").split()]
        _assert_same_pose(make_T(matrix_from_rpy(rpy), xyz), T)
        assert "T_parent_child" in text and "OPTICAL" in text


# ---------------------------------------------------------------------- tf2
def test_tf2_arguments_are_T_lidar_camera(rng):
    for T in [T_LIDAR_CAMERA_RIG, *random_pose(rng, size=20)]:
        pose2, parent2, child2 = _pose_from_ros2_args(tf2_arguments(T, ros=2))
        pose1, parent1, child1 = _pose_from_ros1_args(tf2_arguments(T, ros=1))
        _assert_same_pose(pose2, T)
        _assert_same_pose(pose1, T)
        assert (parent1, child1) == (parent2, child2) == ("lidar", "camera")


def test_tf2_arguments_keep_the_stored_numbers():
    values = [0.1, -0.2, 0.3, 0.0, 0.0, math.sqrt(0.5), math.sqrt(0.5)]
    args = tf2_arguments(pose_from_xyz_quat(values), ros=1)
    assert [float(a) for a in args[:3]] == values[:3]
    assert_allclose([float(a) for a in args[3:7]], values[3:], **TOL["transform"])


def test_tf2_text_commands_parse_back(rng):
    T = random_pose(rng)
    text = tf2_text(T, parent_frame="os_sensor", child_frame="cam_optical")
    lines = [
        line.lstrip("# ") for line in text.splitlines() if "static_transform_publisher " in line
    ]
    assert len(lines) == 3
    ros2_new, ros2_old, ros1 = (shlex.split(line) for line in lines)
    assert ros2_new[:4] == ["ros2", "run", "tf2_ros", "static_transform_publisher"]
    assert ros1[:3] == ["rosrun", "tf2_ros", "static_transform_publisher"]
    pose, parent, child = _pose_from_ros2_args(ros2_new[4:])
    _assert_same_pose(pose, T)
    assert (parent, child) == ("os_sensor", "cam_optical")
    for args in (ros2_old[4:], ros1[3:]):
        pose, parent, child = _pose_from_ros1_args(args)
        _assert_same_pose(pose, T)
        assert (parent, child) == ("os_sensor", "cam_optical")
    # the active (uncommented) command is the ROS 2 one; the convention is spelled out
    active = [line for line in text.splitlines() if line and not line.startswith("#")]
    assert len(active) == 1 and active[0].startswith("ros2 run")
    assert "p_parent = T_parent_child @ p_child" in text and "OPTICAL" in text


def test_ros2_launch_snippet_parses_back(rng):
    T = random_pose(rng)
    text = ros2_launch_text(T, parent_frame="lidar_link", child_frame="camera_optical")
    tree = ast.parse(text)  # valid Python
    node = next(
        n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", "") == "Node"
    )
    keywords = {k.arg: k.value for k in node.keywords}
    assert ast.literal_eval(keywords["package"]) == "tf2_ros"
    assert ast.literal_eval(keywords["executable"]) == "static_transform_publisher"
    pose, parent, child = _pose_from_ros2_args(ast.literal_eval(keywords["arguments"]))
    _assert_same_pose(pose, T)
    assert (parent, child) == ("lidar_link", "camera_optical")


@pytest.mark.parametrize("names", [("lidar", "lidar"), ("lidar", "cam era"), ("a--b", "c")])
def test_bad_frame_names_are_input_errors(names):
    with pytest.raises(InputError):
        tf2_arguments(np.eye(4), parent_frame=names[0], child_frame=names[1])
    with pytest.raises(InputError):
        urdf_text(np.eye(4), parent_frame=names[0], child_frame=names[1])


def test_not_a_transform_is_a_value_error():
    with pytest.raises(ValueError):
        tf2_arguments(np.ones((4, 4)))


# ---------------------------------------------------------------------- OpenCV YAML
def _read_storage(path):
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert storage.isOpened()
    try:
        values = {
            "width": int(storage.getNode("image_width").real()),
            "height": int(storage.getNode("image_height").real()),
            "distortion_model": storage.getNode("distortion_model").string(),
            "camera_model": storage.getNode("camera_model").string(),
        }
        for key in ("camera_matrix", "distortion_coefficients", "T_camera_lidar", "R", "t"):
            values[key] = storage.getNode(key).mat()
        values["rvec"] = storage.getNode("rvec").mat()
        values["T_lidar_camera"] = storage.getNode("T_lidar_camera").mat()
    finally:
        storage.release()
    return values


def test_opencv_yaml_round_trip_with_filestorage(tmp_path, rng):
    camera = example_camera("plumb_bob")
    T_camera_lidar = invert_T(T_LIDAR_CAMERA_RIG)
    path = tmp_path / "camera.yaml"
    path.write_text(opencv_yaml_text(camera, T_camera_lidar))
    values = _read_storage(path)
    assert (values["width"], values["height"]) == (camera.width, camera.height)
    assert values["distortion_model"] == "plumb_bob" and values["camera_model"] == "plumb_bob"
    assert_allclose(values["camera_matrix"], camera.K, rtol=0, atol=0)
    assert_allclose(values["distortion_coefficients"].ravel(), camera.distortion_coeffs, atol=0)
    assert_allclose(values["T_camera_lidar"], T_camera_lidar, rtol=0, atol=0)
    assert_allclose(values["R"], T_camera_lidar[:3, :3], rtol=0, atol=0)
    assert_allclose(values["t"].ravel(), T_camera_lidar[:3, 3], rtol=0, atol=0)
    assert_allclose(cv2.Rodrigues(values["rvec"])[0], T_camera_lidar[:3, :3], **TOL["transform"])
    assert_allclose(values["T_lidar_camera"], T_LIDAR_CAMERA_RIG, **TOL["transform"])
    # OpenCV's own projection with the exported values = nbcalib's projection
    points_lidar = rng.uniform([2.0, -3.0, -1.0], [20.0, 3.0, 1.0], size=(200, 3))
    uv, valid = camera.project(transform_points(T_camera_lidar, points_lidar))
    uv_cv, _ = cv2.projectPoints(
        points_lidar,
        values["rvec"],
        values["t"],
        values["camera_matrix"],
        values["distortion_coefficients"],
    )
    assert valid.sum() > 100
    assert_allclose(uv_cv.reshape(-1, 2)[valid], uv[valid], **TOL["camera_vs_opencv_px"])


@pytest.mark.parametrize(
    "model", ["pinhole", "plumb_bob", "rational_polynomial", "fisheye", "omnidir", "atan"]
)
def test_opencv_yaml_reads_back_with_the_camera_loader(tmp_path, rng, model):
    camera = example_camera(model)
    path = tmp_path / "camera.yaml"
    path.write_text(opencv_yaml_text(camera, np.eye(4)))
    loaded = load_camera(path)
    assert (loaded.width, loaded.height) == (camera.width, camera.height)
    # pinhole comes back as plumb_bob with zero distortion: the same projection
    expected_model = "plumb_bob" if model == "pinhole" else camera.model
    assert loaded.model == expected_model
    points = rng.uniform([-1.0, -1.0, 2.0], [1.0, 1.0, 5.0], size=(100, 3))
    uv, valid = camera.project(points)
    uv_loaded, valid_loaded = loaded.project(points)
    assert np.array_equal(valid, valid_loaded) and valid.any()
    assert_allclose(uv_loaded[valid], uv[valid], **TOL["camera_roundtrip_px"])


# ---------------------------------------------------------------------- work directory
def test_export_result_writes_every_format(tmp_path, rng):
    camera = example_camera("plumb_bob")
    T_final, T_auto = random_pose(rng), random_pose(rng)
    workdir = _workdir(
        tmp_path, camera, {"init_T_lidar_camera_auto": T_auto, "T_lidar_camera": T_final}
    )
    written = export_result(workdir)
    assert [p.name for p in written] == [name for names in FILE_NAMES.values() for name in names]
    assert all(p.parent == workdir / "export" and p.stat().st_size > 0 for p in written)
    pose, _, _ = _pose_from_ros2_args(
        shlex.split(
            next(
                line
                for line in (workdir / "export/tf2_static_transform.sh").read_text().splitlines()
                if line.startswith("ros2 run")
            )
        )[4:]
    )
    _assert_same_pose(pose, invert_T(T_final))  # latest = final; tf2 holds T_lidar_camera
    values = _read_storage(workdir / "export/camera_lidar_opencv.yaml")
    assert_allclose(values["T_camera_lidar"], T_final, **TOL["transform"])

    out = tmp_path / "auto_out"
    (yaml_path,) = export_result(workdir, ("opencv",), out, stage="auto")
    assert yaml_path == out / "camera_lidar_opencv.yaml"
    assert_allclose(_read_storage(yaml_path)["T_camera_lidar"], T_auto, **TOL["transform"])


def test_stage_selection_and_missing_results(tmp_path, rng):
    T_auto = random_pose(rng)
    workdir = _workdir(tmp_path, example_camera("pinhole"), {"init_T_lidar_camera_auto": T_auto})
    calib, key = load_result(workdir)
    assert key == "init_T_lidar_camera_auto" and calib.path == workdir / "calib.json"
    for stage, hint in (("final", "nbcalib calibrate"), ("init", r"run\.manual")):
        with pytest.raises(InputError, match=hint):
            load_result(workdir, stage=stage)
    with pytest.raises(InputError, match="work directory not found"):
        load_result(tmp_path / "nowhere")
    with pytest.raises(InputError, match="nbcalib preprocess"):
        load_result(tmp_path)
    with pytest.raises(ValueError):
        export_result(workdir, ("png",))


def test_export_command(tmp_path, rng, capsys):
    T = random_pose(rng)
    workdir = _workdir(tmp_path, example_camera("fisheye"), {"T_lidar_camera": T})
    status = main(
        [
            "export",
            str(workdir),
            "--format",
            "urdf",
            "--out",
            str(tmp_path / "o"),
            "--parent-frame",
            "base_lidar",
            "--child-frame",
            "cam_optical",
        ]
    )
    assert status == 0
    out = capsys.readouterr().out
    assert "lidar_camera.urdf" in out and "ROS 2" not in out
    joint = ET.parse(tmp_path / "o" / "lidar_camera.urdf").getroot().find("joint")
    assert joint.find("parent").get("link") == "base_lidar"

    assert main(["export", str(workdir), "--format", "tf2"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("ROS 2: "))
    pose, _, _ = _pose_from_ros2_args(shlex.split(line)[6:])
    _assert_same_pose(pose, invert_T(T))


def test_export_command_user_errors_exit_2(tmp_path, capsys):
    assert main(["export", str(tmp_path / "missing")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing" in err and "Traceback" not in err
    workdir = _workdir(tmp_path, example_camera("pinhole"), {})
    assert main(["export", str(workdir)]) == 2
    assert "calib.json" in capsys.readouterr().err
