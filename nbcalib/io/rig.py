"""Camera rigs: several cameras with known camera-to-camera extrinsics (issue 32's ``--rig``).

:func:`read_rig` reads either format below, recognised by its content; :func:`save_rig` writes
nbcalib's own, which :func:`read_rig` reads back (the cameras exactly, the poses to
rounding).

**nbcalib's rig YAML** (or JSON for ``.json``)::

    cameras:
      - name: front
        camera_model: plumb_bob          # any nbcalib camera model, its parameter layout
        intrinsics: [fx, fy, cx, cy]
        distortion_coeffs: [k1, k2, p1, p2, k3]
        width: 1280
        height: 960
        T_rig_camera: [x, y, z, qx, qy, qz, qw]   # the camera's pose in the rig frame
        topic: /front/image_raw          # optional
      - ...

``T_rig_camera`` maps points in the camera's frame into the rig's, stored like the reference
toolbox's ``T_lidar_camera`` (metres, quaternion xyzw); the rig frame is any frame the poses
share (the first camera's, a vehicle's).

:func:`read_kalibr_camchain` reads a **Kalibr camchain YAML** (``kalibr_calibrate_cameras``'
``camchain-*.yaml``, also the ``camchain-imucam-*.yaml`` of ``kalibr_calibrate_imu_camera``)::

    cam0:
      camera_model: pinhole            # pinhole | omni  (ds, eucm: not supported)
      intrinsics: [fu, fv, pu, pv]     # omni: [xi, fu, fv, pu, pv]
      distortion_model: radtan         # radtan | equidistant | fov | none
      distortion_coeffs: [k1, k2, r1, r2]
      resolution: [width, height]
      rostopic: /cam0/image_raw
    cam1:
      T_cn_cnm1: [[...4 x 4...]]       # maps points of cam0's frame into cam1's
      ...

Kalibr's models map onto nbcalib's (docs/conventions.md section 7): pinhole + radtan is
``plumb_bob`` (``k3 = 0``), pinhole + none ``pinhole``, pinhole + equidistant ``fisheye``
(Kannala-Brandt, as OpenCV's), pinhole + fov ``atan`` (Devernay-Faugeras' FOV model, the same
``omega``), omni + radtan or none ``omnidir`` (Mei's unified model, ``xi`` moved after the
focal lengths and centre). ``T_cn_cnm1`` is ``T_camN_camN-1`` in nbcalib's naming (``T_a_b``
maps points in frame b to frame a); the chain gives every camera's ``T_cam_cam0``.

Every problem with a file is an :class:`~nbcalib.errors.InputError` naming the file and what is
missing or wrong.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError

__all__ = ["Rig", "RigCamera", "read_kalibr_camchain", "read_rig", "save_rig"]

#: How far a given rotation may be from orthonormal (Kalibr writes ~1e-9 digits).
_ORTHONORMAL_TOL = 1e-5

_CAM_KEY = re.compile(r"^cam(\d+)$")


@dataclass(frozen=True)
class RigCamera:
    """One camera of a rig.

    Attributes
    ----------
    name : str
        Its name in the file (Kalibr's ``cam0``, ``cam1``, ...).
    camera : CameraModel
        Its model, intrinsics and image size.
    T_cam_cam0 : ndarray of shape (4, 4)
        Maps points in the first camera's frame into this camera's (identity for the first).
    topic : str or None
        Its image topic (Kalibr's ``rostopic``), if given.
    """

    name: str
    camera: object
    T_cam_cam0: np.ndarray
    topic: str | None = None


@dataclass(frozen=True)
class Rig:
    """Cameras with known camera-to-camera extrinsics, the first camera the rig's frame."""

    cameras: tuple[RigCamera, ...]

    def names(self) -> list[str]:
        """The cameras' names, in the file's order."""
        return [c.name for c in self.cameras]

    def T(self, a: str, b: str) -> np.ndarray:
        """``T_a_b``: maps points in camera ``b``'s frame into camera ``a``'s."""
        from nbcalib.transforms import invert_T

        by_name = {c.name: c for c in self.cameras}
        for name in (a, b):
            if name not in by_name:
                raise KeyError(f"no camera {name!r} in the rig (it has {', '.join(by_name)})")
        return by_name[a].T_cam_cam0 @ invert_T(by_name[b].T_cam_cam0)


def read_rig(path: str | os.PathLike) -> Rig:
    """Read a rig file: nbcalib's rig YAML/JSON or a Kalibr camchain YAML (module docstring).

    Raises
    ------
    InputError
        Missing or unreadable file, neither format, or any problem of the format it is.
    """
    data = _read_mapping(Path(path))
    if "cameras" in data:
        return _nbcalib_rig(data, Path(path))
    if any(_CAM_KEY.match(str(key)) for key in data):
        return read_kalibr_camchain(path)
    raise InputError(
        "not a rig file: expected nbcalib's 'cameras' list or a Kalibr camchain's cam0, cam1, ...",
        path,
    )


def save_rig(path: str | os.PathLike, rig: Rig) -> None:
    """Write ``rig`` in nbcalib's rig format (YAML, or JSON for ``.json``), atomically.

    The rig frame written is the first camera's: ``T_rig_camera`` is each camera's
    ``T_cam0_cam``.
    """
    import json

    import yaml

    from nbcalib.io._files import write_text_atomic
    from nbcalib.transforms import invert_T, pose_to_xyz_quat

    cameras = []
    for c in rig.cameras:
        entry = {"name": c.name, **c.camera.to_dict()}
        entry["T_rig_camera"] = [float(x) for x in pose_to_xyz_quat(invert_T(c.T_cam_cam0))]
        if c.topic is not None:
            entry["topic"] = c.topic
        cameras.append(entry)
    data = {"cameras": cameras}
    path = Path(path)
    if path.suffix.lower() == ".json":
        text = json.dumps(data, indent=2) + "\n"
    else:
        text = (
            "# nbcalib rig (nbcalib.io.rig): T_rig_camera maps camera points into the rig frame\n"
        )
        text += yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    write_text_atomic(path, text)


def _read_mapping(path: Path) -> dict:
    """The file parsed (JSON or YAML) into a dict."""
    from nbcalib.io.calib_json import read_json
    from nbcalib.io.camera_file import _read_yaml

    if not path.is_file():
        what = "is a directory, expected" if path.is_dir() else "not found:"
        raise InputError(f"{what} a rig file", path)
    data = read_json(path) if path.suffix.lower() == ".json" else _read_yaml(path)
    if not isinstance(data, dict):
        raise InputError("not a rig file: expected a mapping of keys to values", path)
    return data


def _nbcalib_rig(data: dict, path: Path) -> Rig:
    """The rig of nbcalib's format (module docstring)."""
    from nbcalib.io.camera_file import _nbcalib_camera, _numbers
    from nbcalib.transforms import invert_T, pose_from_xyz_quat

    entries = data["cameras"]
    if not isinstance(entries, list) or not entries:
        raise InputError("'cameras' must be a non-empty list of cameras", path)
    cameras, poses = [], []
    for k, entry in enumerate(entries):
        where = f"cameras[{k}]"
        if not isinstance(entry, dict):
            raise InputError(f"{where} must be a mapping of keys to values", path)
        for key in ("name", "camera_model", "intrinsics", "T_rig_camera"):
            if key not in entry:
                raise InputError(f"{where} has no {key}", path)
        name = str(entry["name"])
        if name in (c[0] for c in cameras):
            raise InputError(f"{where}: camera name {name!r} used twice", path)
        try:
            camera = _nbcalib_camera(entry, path, None, None)
        except InputError as exc:
            raise InputError(f"{where} ({name}): {_without_path(exc, path)}", path) from None
        values = _numbers(entry["T_rig_camera"], f"{where}.T_rig_camera", path, 7)
        if not np.linalg.norm(values[3:]) > 0.0:
            raise InputError(f"{where}.T_rig_camera has a zero quaternion", path)
        topic = entry.get("topic")
        cameras.append((name, camera, None if topic is None else str(topic)))
        poses.append(pose_from_xyz_quat(values))
    T_rig_cam0 = poses[0]
    return Rig(
        tuple(
            RigCamera(name, camera, invert_T(T) @ T_rig_cam0, topic)
            for (name, camera, topic), T in zip(cameras, poses)
        )
    )


def _without_path(exc: InputError, path: Path) -> str:
    """The message of an error about ``path``, without its ``path: `` prefix."""
    text = str(exc)
    prefix = f"{path}: "
    return text[len(prefix) :] if text.startswith(prefix) else text


def read_kalibr_camchain(path: str | os.PathLike) -> Rig:
    """Read a Kalibr camchain YAML into a :class:`Rig` (module docstring).

    Raises
    ------
    InputError
        Missing or unreadable file, not a camchain, an unsupported camera or distortion model,
        wrong parameter counts, non-finite numbers, a transform that is not rigid.
    """
    path = Path(path)
    data = _read_mapping(path)
    keys = sorted(
        (int(m.group(1)), key) for key in data if (m := _CAM_KEY.match(str(key))) is not None
    )
    if not keys:
        raise InputError("not a Kalibr camchain: no cam0, cam1, ... entries", path)
    if [k for k, _ in keys] != list(range(len(keys))):
        raise InputError(
            f"cameras {', '.join(key for _, key in keys)}: expected cam0 to cam{len(keys) - 1} "
            "without gaps (each camera's T_cn_cnm1 refers to the one before)",
            path,
        )
    cameras = []
    T_prev_cam0 = np.eye(4)
    for index, key in keys:
        entry = data[key]
        if not isinstance(entry, dict):
            raise InputError(f"{key} must be a mapping of keys to values", path)
        camera = _camera(entry, key, path)
        if index == 0:
            T_cam_cam0 = np.eye(4)
        else:
            if "T_cn_cnm1" not in entry:
                raise InputError(f"{key} has no T_cn_cnm1 (its pose in cam{index - 1}'s)", path)
            T_cam_cam0 = _rigid(entry["T_cn_cnm1"], f"{key}.T_cn_cnm1", path) @ T_prev_cam0
        topic = entry.get("rostopic")
        cameras.append(RigCamera(key, camera, T_cam_cam0, None if topic is None else str(topic)))
        T_prev_cam0 = T_cam_cam0
    return Rig(tuple(cameras))


def _camera(entry: dict, key: str, path: Path):
    """The nbcalib camera of one camchain entry."""
    from nbcalib.camera import create_camera
    from nbcalib.io.camera_file import _numbers

    for field in ("camera_model", "intrinsics", "resolution"):
        if field not in entry:
            raise InputError(f"{key} has no {field}", path)
    kind = str(entry["camera_model"]).lower()
    distortion = str(entry.get("distortion_model", "none")).lower()
    intr = _numbers(entry["intrinsics"], f"{key}.intrinsics", path)
    coeffs = _numbers(entry.get("distortion_coeffs") or [], f"{key}.distortion_coeffs", path)
    size = _numbers(entry["resolution"], f"{key}.resolution", path, 2)
    if any(s != int(s) or s < 1 for s in size):
        raise InputError(f"{key}.resolution must be two positive whole numbers, got {size}", path)
    width, height = int(size[0]), int(size[1])
    counts = {"radtan": 4, "equidistant": 4, "fov": 1, "none": 0}
    if distortion not in counts:
        raise InputError(
            f"{key}: distortion_model {distortion!r} is not supported (radtan, equidistant, "
            "fov or none)",
            path,
        )
    if distortion == "none" and not any(coeffs):  # zeros written for no distortion
        coeffs = []
    if len(coeffs) != counts[distortion]:
        raise InputError(
            f"{key}: distortion_model {distortion} takes {counts[distortion]} "
            f"distortion_coeffs, got {len(coeffs)}",
            path,
        )
    if kind == "pinhole":
        if len(intr) != 4:
            raise InputError(
                f"{key}: a pinhole camera takes 4 intrinsics [fu, fv, pu, pv], got {len(intr)}",
                path,
            )
        model, dist = {
            "none": ("pinhole", []),
            "radtan": ("plumb_bob", [*coeffs, 0.0]),
            "equidistant": ("fisheye", coeffs),
            "fov": ("atan", coeffs),
        }[distortion]
    elif kind == "omni":
        if len(intr) != 5:
            raise InputError(
                f"{key}: an omni camera takes 5 intrinsics [xi, fu, fv, pu, pv], got {len(intr)}",
                path,
            )
        if distortion not in ("radtan", "none"):
            raise InputError(
                f"{key}: an omni camera with distortion_model {distortion} is not supported "
                "(radtan or none)",
                path,
            )
        model, dist, intr = "omnidir", coeffs or [0.0] * 4, [*intr[1:], intr[0]]
    else:
        raise InputError(
            f"{key}: camera_model {kind!r} is not supported (pinhole or omni; ds and eucm "
            "have no nbcalib model)",
            path,
        )
    try:
        return create_camera(model, intr, dist, width, height)
    except ValueError as exc:
        raise InputError(f"{key}: {exc}", path) from None


def _rigid(value, what: str, path: Path) -> np.ndarray:
    """A 4 x 4 rigid transform from a nested list (rotation orthonormal, last row 0 0 0 1)."""
    from nbcalib.io.camera_file import _numbers

    T = np.array(_numbers(value, what, path, 16)).reshape(4, 4)
    R = T[:3, :3]
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=_ORTHONORMAL_TOL):
        raise InputError(f"{what}: the last row must be 0 0 0 1, got {T[3].tolist()}", path)
    if not np.allclose(R.T @ R, np.eye(3), atol=_ORTHONORMAL_TOL) or np.linalg.det(R) <= 0.0:
        raise InputError(f"{what}: not a rotation (orthonormal, determinant +1)", path)
    T[3] = [0.0, 0.0, 0.0, 1.0]
    return T
