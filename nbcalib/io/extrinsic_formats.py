"""Export a calibration result for ROS (tf2, launch, URDF) and OpenCV, convention stated in each.

The result is read from ``WORKDIR/calib.json`` (docs/conventions.md section 4): the stored
``T_lidar_camera`` ``[x, y, z, qx, qy, qz, qw]`` with ``p_lidar = T_lidar_camera @ p_camera``.
Every output names two frames: the *parent* is the LiDAR frame (REP 103 body axes) and the
*child* is the camera **optical** frame (x right, y down, z forward), with names chosen by the
user (default ``lidar`` and ``camera``).

- **tf2** (:func:`tf2_text`, :func:`tf2_arguments`, :func:`ros2_launch_text`): tf2 publishes
  the pose of the child frame in the parent frame, ``T_parent_child`` with
  ``p_parent = T_parent_child @ p_child``. With parent = LiDAR and child = camera, the numbers
  are ``T_lidar_camera`` exactly as stored in calib.json (metres, quaternion xyzw).
- **URDF** (:func:`urdf_text`): a fixed joint whose ``<origin xyz rpy>`` is the same
  ``T_lidar_camera``; ``rpy`` are fixed-axis angles, ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)``
  (:func:`rpy_from_matrix`).
- **OpenCV** (:func:`opencv_yaml_text`): a ``cv::FileStorage`` YAML with the camera (``K``, ``D``,
  image size, distortion model) and the *inverse* direction, the one ``cv2.projectPoints``
  wants: ``T_camera_lidar`` (``p_camera = T_camera_lidar @ p_lidar``), its ``R``, ``t`` and
  ``rvec``. :func:`nbcalib.io.camera_file.load_camera` reads the camera back.

:func:`export_result` writes the files; ``nbcalib export`` is its command line.

A several-camera work directory (``WORK/rig.json``, :mod:`nbcalib.rig_pipeline`) exports every
camera in one tree (:func:`export_rig`): one tf2 script and one launch file publishing each
camera's optical frame (named after the camera) as a child of the LiDAR frame, one URDF with a
fixed joint per camera, and each camera's OpenCV YAML in ``export/<camera>/``.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError
from nbcalib.transforms import invert_T, pose_from_xyz_quat, pose_to_xyz_quat, validate_T

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel
    from nbcalib.io.calib_json import CalibFile

#: Export formats, in the order ``--format all`` writes them.
FORMATS = ("tf2", "urdf", "opencv")
#: ``--stage`` names and the calib.json result keys they select.
STAGE_KEYS = {
    "final": "T_lidar_camera",
    "init": "init_T_lidar_camera",
    "auto": "init_T_lidar_camera_auto",
}
#: File names written by :func:`export_result`, per format.
FILE_NAMES = {
    "tf2": ("tf2_static_transform.sh", "static_transform.launch.py"),
    "urdf": ("lidar_camera.urdf",),
    "opencv": ("camera_lidar_opencv.yaml",),
}

# ROS names: letters, digits, underscores and slashes (tf2 ignores a leading slash).
_FRAME_NAME = re.compile(r"^/?[A-Za-z_][A-Za-z0-9_/]*$")
# At or below this cos(pitch) (gimbal lock: roll and yaw turn about the same axis) roll is 0.
_GIMBAL_COS = 1e-12

_TF2_CONVENTION = """\
# Convention: tf2 publishes the pose of the child frame in the parent frame, T_parent_child,
#   p_parent = T_parent_child @ p_child (translation in metres, quaternion qx qy qz qw).
#   parent "{parent}" = the LiDAR frame (REP 103 body axes: x forward, y left, z up);
#   child "{child}" = the camera OPTICAL frame (x right, y down, z forward, as OpenCV).
#   So these numbers are T_lidar_camera [x y z qx qy qz qw], calib.json results.{stage}.
"""


# ---------------------------------------------------------------------- rotations
def rpy_from_matrix(R) -> np.ndarray:
    """URDF / ROS fixed-axis roll, pitch, yaw of a rotation matrix.

    The angles satisfy ``R = Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (rotate about the fixed x axis by
    roll, then about y by pitch, then about z by yaw), as urdfdom's ``Rotation::setFromRPY``
    and tf2's ``Matrix3x3::getRPY``.

    Parameters
    ----------
    R : array_like of shape (3, 3)
        Rotation matrix.

    Returns
    -------
    ndarray of shape (3,), float64
        ``[roll, pitch, yaw]`` in radians; pitch in ``[-pi/2, pi/2]``, roll and yaw in
        ``(-pi, pi]``. At gimbal lock (``cos(pitch) <= 1e-12``, where only ``yaw -/+ roll``
        is defined) roll is 0.

    Notes
    -----
    Camera optical frames sit near pitch = +-90 degrees in a LiDAR frame, where splitting roll
    and yaw with two independent ``atan2`` loses ~1e-7 of ``matrix_from_rpy(rpy) - R`` (the
    entries that give roll are ~cos(pitch) in size). Here yaw is instead fitted, given roll
    and pitch, to the four entries that stay large, which keeps the round trip at ~1e-12.
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"R must be a finite 3 x 3 rotation matrix, got shape {R.shape}")
    # cos(pitch) from the first column; more accurate near the lock than from the last row
    cos_pitch = math.hypot(R[0, 0], R[1, 0])
    pitch = math.atan2(-R[2, 0], cos_pitch)
    # Near the lock roll is ill-conditioned (R[2, 1], R[2, 2] ~ cos(pitch), noisy); any roll
    # works if yaw is made consistent with it, which the least squares below does.
    roll = math.atan2(R[2, 1], R[2, 2]) if cos_pitch > _GIMBAL_COS else 0.0
    # yaw from the four entries that do not vanish at the lock, given roll and pitch:
    # M @ [cos yaw, sin yaw] = [R01, R11, R02, R12] with M^T M = (1 + sin^2 pitch) I
    sr, cr, sp = math.sin(roll), math.cos(roll), math.sin(pitch)
    cos_yaw = sp * sr * R[0, 1] + cr * R[1, 1] + sp * cr * R[0, 2] - sr * R[1, 2]
    sin_yaw = -cr * R[0, 1] + sp * sr * R[1, 1] + sr * R[0, 2] + sp * cr * R[1, 2]
    yaw = math.atan2(sin_yaw, cos_yaw)
    return np.array([roll, pitch, yaw])


def matrix_from_rpy(rpy) -> np.ndarray:
    """Rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` of URDF ``rpy`` (inverse of the above).

    Parameters
    ----------
    rpy : array_like of shape (3,)
        ``[roll, pitch, yaw]`` in radians.

    Returns
    -------
    ndarray of shape (3, 3), float64
    """
    roll, pitch, yaw = np.asarray(rpy, dtype=np.float64).reshape(3)
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    return Rz @ Ry @ Rx


# ---------------------------------------------------------------------- tf2
def tf2_arguments(
    T_lidar_camera, *, parent_frame: str = "lidar", child_frame: str = "camera", ros: int = 2
) -> list[str]:
    """Arguments of ``static_transform_publisher`` for the extrinsic.

    Parameters
    ----------
    T_lidar_camera : array_like of shape (4, 4)
        ``p_lidar = T_lidar_camera @ p_camera``; the pose of the camera (child) in the LiDAR
        frame (parent), which is what tf2 publishes.
    parent_frame, child_frame : str, keyword-only
        tf2 frame names of the LiDAR frame and of the camera optical frame.
    ros : {1, 2}, keyword-only
        ROS 1 (``rosrun tf2_ros static_transform_publisher x y z qx qy qz qw parent child``) or
        ROS 2 Humble and later (``--x .. --qw .. --frame-id parent --child-frame-id child``).

    Returns
    -------
    list of str
        The arguments after ``static_transform_publisher``.
    """
    _check_frames(parent_frame, child_frame)
    x, y, z, qx, qy, qz, qw = (_number(v) for v in pose_to_xyz_quat(_transform(T_lidar_camera)))
    if ros == 1:
        return [x, y, z, qx, qy, qz, qw, parent_frame, child_frame]
    if ros == 2:
        values = {"x": x, "y": y, "z": z, "qx": qx, "qy": qy, "qz": qz, "qw": qw}
        args = [item for key, value in values.items() for item in (f"--{key}", value)]
        return [*args, "--frame-id", parent_frame, "--child-frame-id", child_frame]
    raise ValueError(f"ros must be 1 or 2, got {ros!r}")


def tf2_text(
    T_lidar_camera,
    *,
    parent_frame: str = "lidar",
    child_frame: str = "camera",
    stage: str = "T_lidar_camera",
) -> str:
    """A shell file with the ROS 2 command, and the ROS 2 (old) and ROS 1 forms as comments.

    Parameters
    ----------
    T_lidar_camera : array_like of shape (4, 4)
        ``p_lidar = T_lidar_camera @ p_camera``.
    parent_frame, child_frame : str, keyword-only
        Names of the LiDAR frame and of the camera optical frame.
    stage : str, keyword-only
        The calib.json result exported, named in the header comment.
    """
    ros2 = tf2_arguments(T_lidar_camera, parent_frame=parent_frame, child_frame=child_frame, ros=2)
    ros1 = tf2_arguments(T_lidar_camera, parent_frame=parent_frame, child_frame=child_frame, ros=1)
    convention = _TF2_CONVENTION.format(parent=parent_frame, child=child_frame, stage=stage)
    return (
        "#!/bin/sh\n"
        "# nbcalib export (tf2): the LiDAR-camera extrinsic as a static transform.\n"
        f"{convention}"
        "\n# ROS 2 (Humble and later):\n"
        f"ros2 run tf2_ros static_transform_publisher {' '.join(ros2)}\n"
        "\n# ROS 2 Foxy/Galactic (positional arguments, deprecated since Humble):\n"
        f"# ros2 run tf2_ros static_transform_publisher {' '.join(ros1)}\n"
        "\n# ROS 1 (tf2_ros; same order: x y z qx qy qz qw parent child):\n"
        f"# rosrun tf2_ros static_transform_publisher {' '.join(ros1)}\n"
    )


def ros2_launch_text(
    T_lidar_camera,
    *,
    parent_frame: str = "lidar",
    child_frame: str = "camera",
    stage: str = "T_lidar_camera",
) -> str:
    """A ROS 2 Python launch file that publishes the extrinsic with static_transform_publisher.

    Parameters are those of :func:`tf2_text`; the arguments are the ROS 2 form of
    :func:`tf2_arguments`.
    """
    arguments = _launch_arguments(T_lidar_camera, parent_frame, child_frame)
    convention = _TF2_CONVENTION.format(parent=parent_frame, child=child_frame, stage=stage)
    return (
        '"""nbcalib export: publish the LiDAR-camera extrinsic as a static tf2 transform.\n\n'
        "ros2 launch ./static_transform.launch.py\n"
        '"""\n\n'
        f"{convention}\n"
        "from launch import LaunchDescription\n"
        "from launch_ros.actions import Node\n\n\n"
        "def generate_launch_description():\n"
        "    return LaunchDescription(\n"
        "        [\n"
        "            Node(\n"
        '                package="tf2_ros",\n'
        '                executable="static_transform_publisher",\n'
        '                name="nbcalib_lidar_camera_static_tf",\n'
        "                arguments=[\n"
        f"{arguments}"
        "                ],\n"
        "            )\n"
        "        ]\n"
        "    )\n"
    )


def _launch_arguments(T_lidar_camera, parent_frame: str, child_frame: str) -> str:
    """A launch file Node's ``arguments`` lines: the ROS 2 form of :func:`tf2_arguments`."""
    args = tf2_arguments(T_lidar_camera, parent_frame=parent_frame, child_frame=child_frame, ros=2)
    pairs = [f'"{args[i]}", "{args[i + 1]}"' for i in range(0, len(args), 2)]
    return "".join(f"                    {pair},\n" for pair in pairs)


# ---------------------------------------------------------------------- URDF
def urdf_text(
    T_lidar_camera,
    *,
    parent_frame: str = "lidar",
    child_frame: str = "camera",
    stage: str = "T_lidar_camera",
) -> str:
    """A URDF with the fixed joint parent (LiDAR) -> child (camera optical frame).

    Parameters
    ----------
    T_lidar_camera : array_like of shape (4, 4)
        ``p_lidar = T_lidar_camera @ p_camera``: the joint origin (pose of the child link in the
        parent link).
    parent_frame, child_frame : str, keyword-only
        Link names of the LiDAR frame and of the camera optical frame.
    stage : str, keyword-only
        The calib.json result exported, named in the comment.

    Returns
    -------
    str
        A complete ``<robot>`` with the two links and the joint; copy the ``<joint>`` into a
        robot description.
    """
    _check_frames(parent_frame, child_frame)
    parent, child = parent_frame.lstrip("/"), child_frame.lstrip("/")
    joint = _urdf_joint(parent, child, T_lidar_camera)
    return f"""\
<?xml version="1.0"?>
<!-- nbcalib export (URDF): the LiDAR-camera extrinsic as a fixed joint, results.{stage}.
     Convention: a joint origin is the pose of the child link in the parent link, T_parent_child,
     p_parent = T_parent_child @ p_child: xyz in metres, rpy in radians as fixed-axis angles,
     R = Rz(yaw) @ Ry(pitch) @ Rx(roll). Parent "{parent}" is the LiDAR frame (REP 103 body
     axes); child "{child}" is the camera OPTICAL frame (x right, y down, z forward), so the
     origin is T_lidar_camera. Copy the joint into your robot; the links make the file valid. -->
<robot name="nbcalib_extrinsic">
  <link name="{parent}"/>
  <link name="{child}"/>
{joint}
</robot>
"""


def _urdf_joint(parent: str, child: str, T_lidar_camera) -> str:
    """The fixed ``<joint>`` element (indented, no final newline) of a URDF export."""
    T = _transform(T_lidar_camera)
    xyz = " ".join(_number(v) for v in T[:3, 3])
    rpy = " ".join(_number(v) for v in rpy_from_matrix(T[:3, :3]))
    return (
        f'  <joint name="{parent}_to_{child}" type="fixed">\n'
        f'    <parent link="{parent}"/>\n'
        f'    <child link="{child}"/>\n'
        f'    <origin xyz="{xyz}" rpy="{rpy}"/>\n'
        "  </joint>"
    )


# ---------------------------------------------------------------------- OpenCV
def opencv_yaml_text(camera: CameraModel, T_camera_lidar, *, stage: str = "T_lidar_camera") -> str:
    """An OpenCV ``cv::FileStorage`` YAML with the camera and the extrinsic.

    Keys: ``image_width``, ``image_height``, ``camera_model`` (nbcalib's name),
    ``distortion_model`` (the ROS name: plumb_bob, rational_polynomial, equidistant = OpenCV
    fisheye, or nbcalib's for the others), ``camera_matrix`` (K, 3 x 3),
    ``distortion_coefficients`` (D, 1 x N, OpenCV order), ``T_camera_lidar`` (4 x 4), ``R``
    (3 x 3), ``t`` (3 x 1, metres), ``rvec`` (3 x 1 Rodrigues vector of R) and ``T_lidar_camera``
    (4 x 4, the inverse). ``cv2.projectPoints(points_lidar, rvec, t, K, D)`` projects LiDAR
    points for plumb_bob and rational_polynomial cameras (``cv2.fisheye.projectPoints`` for
    equidistant).

    Parameters
    ----------
    camera : CameraModel
        The camera of the work directory.
    T_camera_lidar : array_like of shape (4, 4)
        ``p_camera = T_camera_lidar @ p_lidar``.
    stage : str, keyword-only
        The calib.json result exported, named in the comment.

    Returns
    -------
    str
        The YAML text (``%YAML`` header and ``!!opencv-matrix`` entries, as OpenCV writes it).
    """
    import cv2

    from nbcalib.camera import camera_to_camera_info

    T_camera_lidar = _transform(T_camera_lidar)
    info = camera_to_camera_info(camera)
    R = T_camera_lidar[:3, :3]
    t = T_camera_lidar[:3, 3:4]
    rvec, _ = cv2.Rodrigues(R)
    comments = [
        f"nbcalib export (OpenCV): camera and LiDAR-camera extrinsic (calib.json results.{stage}).",
        "Convention: p_camera = T_camera_lidar @ p_lidar = R @ p_lidar + t (metres); camera",
        "frame optical (x right, y down, z forward); pixel centres at integers (OpenCV).",
        "cv2.projectPoints(points_lidar, rvec, t, camera_matrix, distortion_coefficients)",
        "projects LiDAR points. T_lidar_camera = inverse, as stored in calib.json.",
        "distortion_model equidistant = cv2.fisheye (k1..k4); omnidir D = [xi, k1, k2, p1, p2].",
    ]
    storage = cv2.FileStorage(".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    for line in comments:
        storage.writeComment(line)
    storage.write("image_width", int(camera.width))
    storage.write("image_height", int(camera.height))
    storage.write("camera_model", str(camera.model))
    storage.write("distortion_model", info["distortion_model"])
    storage.write("camera_matrix", np.asarray(info["K"], dtype=np.float64).reshape(3, 3))
    storage.write("distortion_coefficients", np.asarray(info["D"], dtype=np.float64).reshape(1, -1))
    storage.write("T_camera_lidar", T_camera_lidar)
    storage.write("R", np.ascontiguousarray(R))
    storage.write("t", np.ascontiguousarray(t))
    storage.write("rvec", np.asarray(rvec, dtype=np.float64).reshape(3, 1))
    storage.write("T_lidar_camera", invert_T(T_camera_lidar))
    return storage.releaseAndGetString()


# ---------------------------------------------------------------------- work directory
def load_result(workdir: str | os.PathLike, *, stage: str = "latest") -> tuple[CalibFile, str]:
    """Read ``WORKDIR/calib.json`` and choose the result to export.

    Parameters
    ----------
    workdir : str or PathLike
        The work directory.
    stage : {"latest", "final", "init", "auto"}, keyword-only
        ``final`` = ``T_lidar_camera``, ``init`` = ``init_T_lidar_camera`` (manual guess),
        ``auto`` = ``init_T_lidar_camera_auto``; ``latest`` = the final result if present, else
        the most recently written initial guess.

    Returns
    -------
    calib : CalibFile
    key : str
        The calib.json result key chosen; ``calib.get_T_camera_lidar(key)`` is the pose.

    Raises
    ------
    InputError
        No work directory, no calib.json, or no such result (naming the stage to run).
    """
    from nbcalib.io.calib_json import read_calib_json

    if stage != "latest" and stage not in STAGE_KEYS:
        raise ValueError(f"stage must be 'latest' or one of {tuple(STAGE_KEYS)}, got {stage!r}")
    workdir = Path(workdir)
    if not workdir.is_dir():
        raise InputError("work directory not found", workdir)
    calib_path = workdir / "calib.json"
    if not calib_path.is_file():
        raise InputError("no calib.json: run 'nbcalib preprocess' first", calib_path)
    calib = read_calib_json(calib_path)
    key = calib.latest_stage() if stage == "latest" else STAGE_KEYS[stage]
    if key is None or not calib.has_result(key):
        hint = {
            "T_lidar_camera": "run 'nbcalib calibrate' first",
            "init_T_lidar_camera": (
                "run 'nbcalib initial-guess' with picked points (run.manual) first"
            ),
            "init_T_lidar_camera_auto": "run 'nbcalib initial-guess' first",
            None: "run 'nbcalib initial-guess' or 'nbcalib calibrate' first",
        }[key]
        raise InputError(f"no result {key or 'at all'} to export; {hint}", calib_path)
    return calib, key


def export_result(
    workdir: str | os.PathLike,
    formats=FORMATS,
    out_dir: str | os.PathLike | None = None,
    *,
    stage: str = "latest",
    parent_frame: str = "lidar",
    child_frame: str = "camera",
) -> list[Path]:
    """Write the chosen result of a work directory in the given formats.

    Parameters
    ----------
    workdir : str or PathLike
        Work directory with a ``calib.json``.
    formats : sequence of {"tf2", "urdf", "opencv"}
        What to write (:data:`FILE_NAMES` lists the files per format).
    out_dir : str or PathLike, optional
        Output folder, created if needed (default ``WORKDIR/export``).
    stage : {"latest", "final", "init", "auto"}, keyword-only
        Which result (:func:`load_result`).
    parent_frame, child_frame : str, keyword-only
        Names of the LiDAR frame and of the camera optical frame in the ROS outputs.

    Returns
    -------
    list of Path
        The files written, in :data:`FILE_NAMES` order.
    """
    _check_formats(formats)
    _check_frames(parent_frame, child_frame)
    calib, key = load_result(workdir, stage=stage)
    T_camera_lidar = calib.get_T_camera_lidar(key)
    # from the stored values, not by inverting T_camera_lidar back: no round-off added
    T_lidar_camera = pose_from_xyz_quat(calib.results[key])
    texts = {}
    frames = dict(parent_frame=parent_frame, child_frame=child_frame, stage=key)
    if "tf2" in formats:
        texts["tf2_static_transform.sh"] = tf2_text(T_lidar_camera, **frames)
        texts["static_transform.launch.py"] = ros2_launch_text(T_lidar_camera, **frames)
    if "urdf" in formats:
        texts["lidar_camera.urdf"] = urdf_text(T_lidar_camera, **frames)
    if "opencv" in formats:
        camera = calib.result_camera(key)
        texts["camera_lidar_opencv.yaml"] = opencv_yaml_text(camera, T_camera_lidar, stage=key)
    return _write_texts(workdir, out_dir, texts)


# ---------------------------------------------------------------------- helpers
def _check_formats(formats) -> None:
    unknown = [f for f in formats if f not in FORMATS]
    if unknown or not formats:
        raise ValueError(f"formats must be a non-empty subset of {FORMATS}, got {formats!r}")


def _write_texts(workdir, out_dir, texts: dict) -> list[Path]:
    """Write ``{relative name: text}`` into ``out_dir`` (default ``WORKDIR/export``), in order."""
    from nbcalib.io._files import write_text_atomic

    out = Path(workdir) / "export" if out_dir is None else Path(out_dir)
    if out.exists() and not out.is_dir():
        raise InputError("exists and is not a folder", out)
    written = []
    for name, text in texts.items():
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / name, text)
        written.append(out / name)
    return written


def _transform(T) -> np.ndarray:
    return validate_T(np.ascontiguousarray(T, dtype=np.float64), name="T")


def _number(value: float) -> str:
    """Shortest text that reads back to the same float64; no negative zero."""
    value = float(value)
    return repr(0.0 if value == 0.0 else value)


def _check_frames(parent_frame: str, child_frame: str) -> None:
    for what, name in (("parent frame", parent_frame), ("child frame", child_frame)):
        if not isinstance(name, str) or not _FRAME_NAME.match(name):
            raise InputError(
                f"{what} {name!r} is not a ROS frame name (letters, digits, '_' and '/')"
            )
    if parent_frame.lstrip("/") == child_frame.lstrip("/"):
        raise InputError(f"parent and child frame are the same: {parent_frame!r}")


# ---------------------------------------------------------------------- several cameras
#: File names written by :func:`export_rig`, per format (the OpenCV one in a folder per camera).
RIG_FILE_NAMES = {
    "tf2": ("tf2_static_transforms.sh", "static_transforms.launch.py"),
    "urdf": ("lidar_cameras.urdf",),
    "opencv": ("<camera>/camera_lidar_opencv.yaml",),
}


def rig_tf2_text(children, *, parent_frame: str = "lidar", stage: str = "T_lidar_camera") -> str:
    """A shell file starting one ROS 2 static transform publisher per camera.

    ``children``: ``(camera optical frame name, T_lidar_camera)`` per camera.
    """
    convention = _TF2_CONVENTION.format(
        parent=parent_frame, child=", ".join(c for c, _ in children), stage=stage
    )
    lines = []
    for child, T in children:
        ros2 = tf2_arguments(T, parent_frame=parent_frame, child_frame=child, ros=2)
        ros1 = tf2_arguments(T, parent_frame=parent_frame, child_frame=child, ros=1)
        lines.append(
            f"\n# {child} (ROS 1: rosrun tf2_ros static_transform_publisher {' '.join(ros1)})\n"
            f"ros2 run tf2_ros static_transform_publisher {' '.join(ros2)} &\n"
        )
    return (
        "#!/bin/sh\n"
        "# nbcalib export (tf2): every camera's extrinsic as a static transform from the LiDAR.\n"
        f"{convention}" + "".join(lines) + "\nwait\n"
    )


def rig_launch_text(children, *, parent_frame: str = "lidar", stage: str = "T_lidar_camera") -> str:
    """A ROS 2 launch file with one static transform publisher per camera (:func:`rig_tf2_text`)."""
    convention = _TF2_CONVENTION.format(
        parent=parent_frame, child=", ".join(c for c, _ in children), stage=stage
    )
    nodes = []
    for child, T in children:
        arguments = _launch_arguments(T, parent_frame, child)
        nodes.append(
            "            Node(\n"
            '                package="tf2_ros",\n'
            '                executable="static_transform_publisher",\n'
            f'                name="nbcalib_{parent_frame.strip("/").replace("/", "_")}_'
            f'{child.strip("/").replace("/", "_")}_static_tf",\n'
            "                arguments=[\n"
            f"{arguments}"
            "                ],\n"
            "            ),\n"
        )
    return (
        '"""nbcalib export: publish every camera\'s extrinsic as a static tf2 transform.\n\n'
        "ros2 launch ./static_transforms.launch.py\n"
        '"""\n\n'
        f"{convention}\n"
        "from launch import LaunchDescription\n"
        "from launch_ros.actions import Node\n\n\n"
        "def generate_launch_description():\n"
        "    return LaunchDescription(\n"
        "        [\n"
        f"{''.join(nodes)}"
        "        ]\n"
        "    )\n"
    )


def rig_urdf_text(children, *, parent_frame: str = "lidar", stage: str = "T_lidar_camera") -> str:
    """A URDF with the LiDAR link and a fixed joint to each camera's optical frame."""
    parent = parent_frame.lstrip("/")
    links, joints = [f'  <link name="{parent}"/>'], []
    for child_frame, T_lidar_camera in children:
        _check_frames(parent_frame, child_frame)
        child = child_frame.lstrip("/")
        links.append(f'  <link name="{child}"/>')
        joints.append(_urdf_joint(parent, child, T_lidar_camera))
    body = "\n".join(links + joints)
    return f"""\
<?xml version="1.0"?>
<!-- nbcalib export (URDF): every camera's LiDAR-camera extrinsic as a fixed joint, results.{stage}
     of each camera's calib.json. Convention: a joint origin is the pose of the child link in the
     parent link, T_parent_child, p_parent = T_parent_child @ p_child: xyz in metres, rpy in
     radians as fixed-axis angles, R = Rz(yaw) @ Ry(pitch) @ Rx(roll). Parent "{parent}" is the
     LiDAR frame (REP 103 body axes); each child is a camera OPTICAL frame (x right, y down,
     z forward), so each origin is that camera's T_lidar_camera. -->
<robot name="nbcalib_extrinsics">
{body}
</robot>
"""


def export_rig(
    workdir: str | os.PathLike,
    cameras,
    formats=FORMATS,
    out_dir: str | os.PathLike | None = None,
    *,
    stage: str = "latest",
    parent_frame: str = "lidar",
) -> list[Path]:
    """Write every camera of a several-camera work directory in one tree (module docstring).

    Parameters
    ----------
    workdir : str or PathLike
        ``WORK``, each camera's work directory ``WORK/<camera>``.
    cameras : sequence of str
        The cameras' names (``rig.json``), also their optical frames' names.
    formats, out_dir, stage, parent_frame
        As for :func:`export_result` (``out_dir`` default ``WORK/export``).

    Returns
    -------
    list of Path
        The files written.
    """
    _check_formats(formats)
    children, texts, keys = [], {}, set()
    for name in cameras:
        _check_frames(parent_frame, name)
        calib, key = load_result(Path(workdir) / name, stage=stage)
        keys.add(key)
        children.append((name, pose_from_xyz_quat(calib.results[key])))
        if "opencv" in formats:
            texts[f"{name}/camera_lidar_opencv.yaml"] = opencv_yaml_text(
                calib.result_camera(key), calib.get_T_camera_lidar(key), stage=key
            )
    key = keys.pop() if len(keys) == 1 else "/".join(sorted(keys))
    if "tf2" in formats:
        texts["tf2_static_transforms.sh"] = rig_tf2_text(
            children, parent_frame=parent_frame, stage=key
        )
        texts["static_transforms.launch.py"] = rig_launch_text(
            children, parent_frame=parent_frame, stage=key
        )
    if "urdf" in formats:
        texts["lidar_cameras.urdf"] = rig_urdf_text(children, parent_frame=parent_frame, stage=key)
    ordered = sorted(texts.items(), key=lambda item: ("/" in item[0], item[0]))
    return _write_texts(workdir, out_dir, dict(ordered))
