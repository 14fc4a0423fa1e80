"""Camera files: load a camera from the formats users have, save nbcalib's own.

:func:`load_camera` reads, recognising the format from the content:

- a **ROS camera_info YAML** (``camera_calibration_parsers``: ``image_width``, ``image_height``,
  ``camera_matrix: {rows, cols, data}``, ``distortion_model``, ``distortion_coefficients``), or a
  dumped ``CameraInfo`` message (``width``, ``height``, ``distortion_model``, ``K``/``k``,
  ``D``/``d``);
- an **nbcalib camera YAML/JSON** (``camera_model``, ``intrinsics``, ``distortion_coeffs``,
  ``width``, ``height``), the format :func:`save_camera` writes;
- an **OpenCV FileStorage** file (``%YAML:1.0`` or XML; ``camera_matrix``/``K``,
  ``distortion_coefficients``/``D``, ``image_width``/``image_height``; an optional
  ``distortion_model: fisheye`` selects OpenCV's fisheye model), or a plain YAML/JSON with the
  same keys (``K``, ``dist``, ``width``, ``height``, and ``model: fisheye`` for OpenCV's fisheye
  model, as the shared real data's ``calib_normalized.json``);
- a **calib.json** (the camera of a work directory; see :mod:`nbcalib.io.calib_json`).

Parameter layouts are those of docs/conventions.md section 7. Every problem with a file is an
:class:`~nbcalib.errors.InputError` naming the file and what is missing or wrong.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io.calib_json import CalibFile, read_json, write_text_atomic

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel

_HEADER = """\
# nbcalib camera (load with nbcalib.io.camera_file.load_camera, or nbcalib preprocess --camera)
# Conventions (docs/conventions.md, sections 6 and 7):
#   camera frame: optical, x right, y down, z forward; pixel centres at integer (u, v),
#   u = column, v = row; the image spans [-0.5, width - 0.5) x [-0.5, height - 0.5).
#   intrinsics: fx, fy, cx, cy in pixels (omnidir: fx, fy, cx, cy, xi; equirectangular: W, H).
#   distortion_coeffs in OpenCV order: plumb_bob k1, k2, p1, p2, k3; rational_polynomial
#   k1, k2, p1, p2, k3, k4, k5, k6; fisheye k1..k4; atan omega; omnidir k1, k2, p1, p2.
"""

_K_KEYS = ("camera_matrix", "K", "k", "cameraMatrix", "intrinsic_matrix")
_D_KEYS = ("distortion_coefficients", "D", "d", "dist_coeffs", "distCoeffs", "dist", "distortion")
_WIDTH_KEYS = ("image_width", "width", "imageWidth")
_HEIGHT_KEYS = ("image_height", "height", "imageHeight")


def load_camera(
    path: str | os.PathLike, *, width: int | None = None, height: int | None = None
) -> CameraModel:
    """Load a camera from a ROS camera_info YAML, nbcalib or OpenCV camera file, or calib.json.

    Parameters
    ----------
    path : str or PathLike
        The camera file; its format is recognised from the content (module docstring).
    width, height : int, optional
        Image size in pixels, for files that do not store it (a ``calib.json`` written by the
        reference, an OpenCV file without ``image_width``). A size that disagrees with the
        file's is an :class:`~nbcalib.errors.InputError`.

    Returns
    -------
    CameraModel
    """
    path = Path(path)
    if (width is None) != (height is None):
        raise ValueError("give both width and height, or neither")
    data = _read_mapping(path)
    kind = _detect(data)
    if kind == "calib.json":
        return CalibFile.from_dict(data, path=path).camera_model(width, height)
    if kind == "nbcalib":
        return _nbcalib_camera(data, path, width, height)
    if kind == "camera_info":
        return _camera_info_camera(data, path, width, height)
    if kind == "opencv":
        return _opencv_camera(data, path, width, height)
    raise InputError(
        "not a camera file: expected a ROS camera_info YAML (camera_matrix, distortion_model), "
        "an nbcalib camera (camera_model, intrinsics), an OpenCV camera (camera_matrix or K) "
        "or a calib.json",
        path,
    )


def save_camera(path: str | os.PathLike, camera: CameraModel) -> None:
    """Write ``camera`` as an nbcalib camera file (YAML with a header, or JSON for ``.json``).

    Parameters
    ----------
    path : str or PathLike
        Output file, written atomically. A ``.json`` suffix writes JSON, anything else YAML.
    camera : CameraModel
        Written as ``camera_model``, ``width``, ``height``, ``intrinsics``, ``distortion_coeffs``
        (:meth:`CameraModel.to_dict`); :func:`load_camera` reads it back exactly.
    """
    import yaml

    path = Path(path)
    data = {
        "camera_model": str(camera.model),
        "width": int(camera.width),
        "height": int(camera.height),
        "intrinsics": [float(x) for x in np.asarray(camera.intrinsics).ravel()],
        "distortion_coeffs": [float(x) for x in np.asarray(camera.distortion_coeffs).ravel()],
    }
    if path.suffix.lower() == ".json":
        text = json.dumps(data, indent=2) + "\n"
    else:
        text = _HEADER + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    write_text_atomic(path, text)


# ---------------------------------------------------------------------- reading
def _read_mapping(path: Path) -> dict:
    """Parse the file into a dict, with the parser its content calls for."""
    try:
        with open(path, "rb") as stream:
            head = stream.read(4096)
    except FileNotFoundError:
        raise InputError("camera file not found", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a camera file", path) from None
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path) from None
    text_head = head.lstrip(b"\xef\xbb\xbf").lstrip()
    if text_head.startswith(b"%YAML:") or text_head.startswith(b"<?xml"):
        data = _read_opencv_storage(path)
    elif text_head.startswith(b"{") or path.suffix.lower() == ".json":
        data = read_json(path)
    else:
        data = _read_yaml(path)
    if not isinstance(data, dict):
        raise InputError("not a camera file: expected a mapping of keys to values", path)
    return data


def _read_yaml(path: Path) -> Any:
    import yaml

    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError("not a text file (expected YAML or JSON)", path) from None
    if "!!opencv-matrix" in text:
        return _read_opencv_storage(path)
    try:
        return yaml.safe_load(text)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark
        where = f" at line {mark.line + 1} column {mark.column + 1}" if mark else ""
        raise InputError(f"invalid YAML{where}: {exc.problem}", path) from None
    except yaml.YAMLError as exc:
        raise InputError(f"invalid YAML: {exc}", path) from None


def _read_opencv_storage(path: Path) -> dict:
    """Read an OpenCV FileStorage file (YAML 1.0 or XML) into plain Python values."""
    import cv2

    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        opened = storage.isOpened()
    except (cv2.error, SystemError):
        opened = False
    if not opened:
        raise InputError("not a valid OpenCV FileStorage file", path)
    try:
        root = storage.root()
        return {key: _node_value(root.getNode(key)) for key in root.keys()}
    except (cv2.error, SystemError, UnicodeDecodeError) as exc:  # names and strings not UTF-8
        raise InputError(f"cannot read OpenCV FileStorage: {exc}", path) from None
    finally:
        storage.release()


def _node_value(node) -> Any:
    # an !!opencv-matrix stays a map {rows, cols, dt, data} (_numbers takes its data): OpenCV's
    # node.mat() corrupts memory on a damaged one (cols: -3), crashing the process
    if node.isMap():
        return {key: _node_value(node.getNode(key)) for key in node.keys()}
    if node.isSeq():
        return [_node_value(node.at(i)) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return float(node.real())
    if node.isString():
        return node.string()
    return None


def _detect(data: dict) -> str | None:
    if isinstance(data.get("camera"), dict) and "camera_model" in data["camera"]:
        return "calib.json"
    if "camera_model" in data and "intrinsics" in data:
        return "nbcalib"
    has_k = any(key in data for key in _K_KEYS)
    if has_k and "distortion_model" in data:
        return "camera_info"
    if has_k:
        return "opencv"
    return None


# ---------------------------------------------------------------------- formats
def _nbcalib_camera(data: dict, path: Path, width, height) -> CameraModel:
    from nbcalib.camera import create_camera

    model = data["camera_model"]
    if not isinstance(model, str):
        raise InputError("camera_model must be a model name", path)
    intrinsics = _numbers(data["intrinsics"], "intrinsics", path)
    distortion = _numbers(data.get("distortion_coeffs", []), "distortion_coeffs", path)
    file_size = _file_size(data, path, ("width",), ("height",))
    size = _merge_size(file_size, width, height, path)
    try:
        return create_camera(model, intrinsics, distortion, *size)
    except ValueError as exc:
        raise InputError(f"{exc}", path) from None


def _camera_info_camera(data: dict, path: Path, width, height) -> CameraModel:
    from nbcalib.camera import camera_from_camera_info

    model = data["distortion_model"]
    if not isinstance(model, str):
        raise InputError("distortion_model must be a model name", path)
    K = _matrix_entry(data, _K_KEYS, 9, "camera_matrix", path)
    D = _optional_entry(data, _D_KEYS, "distortion_coefficients", path)
    size = _merge_size(_file_size(data, path, _WIDTH_KEYS, _HEIGHT_KEYS), width, height, path)
    try:
        return camera_from_camera_info(
            width=size[0], height=size[1], distortion_model=model, D=D, K=K
        )
    except ValueError as exc:
        raise InputError(f"{exc}", path) from None


def _opencv_camera(data: dict, path: Path, width, height) -> CameraModel:
    from nbcalib.camera import camera_from_opencv

    K = np.reshape(_matrix_entry(data, _K_KEYS, 9, "camera_matrix", path), (3, 3))
    D = _optional_entry(data, _D_KEYS, "distortion_coefficients", path)
    name = next((data[k] for k in ("distortion_model", "camera_model", "model") if k in data), "")
    fisheye = _is_fisheye_name(name)
    size = _file_size(data, path, _WIDTH_KEYS, _HEIGHT_KEYS)
    if size is None and "image_size" in data:
        size = _size_pair(data["image_size"], "image_size", path)
    size = _merge_size(size, width, height, path)
    try:
        return camera_from_opencv(K, np.asarray(D), size[0], size[1], fisheye=fisheye)
    except ValueError as exc:
        raise InputError(f"{exc}", path) from None


# ---------------------------------------------------------------------- values
def _is_fisheye_name(name) -> bool:
    return isinstance(name, str) and name.lower() in ("fisheye", "equidistant")


def _numbers(value, what: str, path: Path, count: int | None = None) -> list[float]:
    """Flatten a list, nested list, array or ``{data: [...]}`` entry to finite floats."""
    if isinstance(value, dict) and "data" in value:  # ROS {rows, cols, data}
        value = value["data"]
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, (list, tuple, np.ndarray)):
        raise InputError(f"{what} must be a list of numbers, got {_short(value)}", path)
    try:
        array = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InputError(f"{what} must be a list of numbers, got {_short(value)}", path) from None
    except OverflowError:  # an integer beyond the range of floats
        raise InputError(f"{what} holds a number too large for a float", path) from None
    if not np.all(np.isfinite(array)):
        raise InputError(f"{what} holds a non-finite number", path)
    if count is not None and array.size != count:
        raise InputError(f"{what} must have {count} numbers, got {array.size}", path)
    return [float(x) for x in array]


def _matrix_entry(data: dict, keys, count: int, what: str, path: Path) -> list[float]:
    for key in keys:
        if key in data:
            return _numbers(data[key], key, path, count)
    raise InputError(f"no {what} (3x3 K)", path)


def _optional_entry(data: dict, keys, what: str, path: Path) -> list[float]:
    for key in keys:
        if key in data and data[key] is not None:
            return _numbers(data[key], key, path)
    return []


def _file_size(data: dict, path: Path, width_keys, height_keys) -> tuple[int, int] | None:
    width = next((data[key] for key in width_keys if key in data), None)
    height = next((data[key] for key in height_keys if key in data), None)
    if width is None and height is None:
        return None
    return _size_pair([width, height], "image width/height", path)


def _size_pair(value, what: str, path: Path) -> tuple[int, int] | None:
    values = _numbers(value, what, path, 2)
    if not all(v >= 0 and float(v).is_integer() for v in values):
        raise InputError(f"{what} must be whole numbers of pixels, got {_short(value)}", path)
    if values[0] == 0 or values[1] == 0:
        return None  # ROS writes 0 x 0 when the size is unknown
    return int(values[0]), int(values[1])


def _merge_size(file_size, width, height, path: Path) -> tuple[int, int]:
    if width is None:
        if file_size is None:
            raise InputError(
                "no image size in the camera file; give the image width and height", path
            )
        return file_size
    if file_size is not None and file_size != (int(width), int(height)):
        raise InputError(
            f"the camera is for {file_size[0]}x{file_size[1]} images, not {width}x{height}", path
        )
    if int(width) <= 0 or int(height) <= 0:
        raise InputError(f"image size must be positive, got {width}x{height}", path)
    return int(width), int(height)


def _short(value) -> str:
    text = json.dumps(value, default=str)
    return text if len(text) <= 60 else text[:57] + "..."
