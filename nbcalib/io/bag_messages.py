"""ROS messages as arrays: the message types nbcalib knows, its rosbags type store, and decoding.

- :func:`typestore`: the ROS 1 (Noetic) or ROS 2 (Humble) type store of ``rosbags`` with the
  Livox ``CustomMsg`` of ``livox_ros_driver2`` and ``livox_ros_driver`` (and, for ROS 1,
  ``tf2_msgs/TFMessage``) added; :mod:`nbcalib.io.bag` reads and :mod:`nbcalib.io.bag_writer`
  writes with it.
- Livox ``CustomMsg`` -> named fields (:func:`parse_livox_raw` straight from the serialised
  bytes, :func:`livox_fields_from_msg` from a deserialised message): ``reflectivity`` is the
  intensity and ``offset_time`` [ns] the per-point time.
- ``sensor_msgs/Image`` (mono8/16, rgb8/16, bgr8/16, rgba/bgra, 8UC1..16UC4, bayer_*, yuv422) and
  ``sensor_msgs/CompressedImage`` -> uint8/uint16 arrays, grey or RGB (:func:`decode_image`,
  :func:`decode_compressed_image`).
- ``sensor_msgs/CameraInfo`` -> :class:`~nbcalib.camera.CameraModel`
  (:func:`camera_from_camera_info_msg`).

The decoders take any object with the message's attributes (a rosbags message or a stand-in), so
they work for ROS 1 and ROS 2 alike. ``sensor_msgs/PointCloud2`` is :mod:`nbcalib.io.pointcloud2`.

CameraInfo for models ROS cannot name (an nbcalib extension; the mapping is
:func:`nbcalib.camera.camera_to_camera_info` / :func:`nbcalib.camera.camera_from_camera_info`):
``distortion_model`` is the nbcalib model name and ``D`` its distortion: ``atan``:
``D = [omega]``; ``omnidir``: ``D = [xi, k1, k2, p1, p2]`` (xi first); ``equirectangular``:
``D = []`` (the intrinsics are the image size). ``pinhole`` is written as ``plumb_bob`` with zero
distortion and ``fisheye`` as ``equidistant``. The reference toolbox takes ``distortion_model`` as
its model name and ``K`` as fx, fy, cx, cy, so it reads all of these except omnidir's ``xi``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError, require
from nbcalib.io._fields import buffer_array, native_columns

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
LIVOX_CUSTOM = ("livox_ros_driver2/msg/CustomMsg", "livox_ros_driver/msg/CustomMsg")

_LIVOX_POINT_MSG = """\
uint32 offset_time
float32 x
float32 y
float32 z
uint8 reflectivity
uint8 tag
uint8 line
"""
_LIVOX_CUSTOM_MSG = """\
std_msgs/Header header
uint64 timebase
uint32 point_num
uint8 lidar_id
uint8[3] rsvd
CustomPoint[] points
"""
_TF_MESSAGE_ROS1 = "geometry_msgs/TransformStamped[] transforms\n"

#: Fields of a Livox ``CustomPoint``, in message order.
LIVOX_FIELDS = ("offset_time", "x", "y", "z", "reflectivity", "tag", "line")
_LIVOX_FORMATS = ("<u4", "<f4", "<f4", "<f4", "u1", "u1", "u1")
_LIVOX_OFFSETS = (0, 4, 8, 12, 16, 17, 18)
_LIVOX_ORDER = ("x", "y", "z", "reflectivity", "tag", "line", "offset_time")  # fields as returned


def _extra_types() -> dict:
    """Livox CustomMsg / CustomPoint of both driver packages, as rosbags type definitions."""
    from rosbags.typesys import get_types_from_msg

    types = {}
    for package in ("livox_ros_driver2", "livox_ros_driver"):
        types.update(get_types_from_msg(_LIVOX_POINT_MSG, f"{package}/msg/CustomPoint"))
        types.update(get_types_from_msg(_LIVOX_CUSTOM_MSG, f"{package}/msg/CustomMsg"))
    return types


def typestore(ros1: bool):
    """Type store (rosbags) for writing (and for ROS 2 bags without embedded definitions).

    Parameters
    ----------
    ros1 : bool
        ROS 1 Noetic's types (with ``tf2_msgs/TFMessage`` added), else ROS 2 Humble's; both with
        the Livox ``CustomMsg`` / ``CustomPoint`` of both driver packages.
    """
    require("rosbags", "bags")
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types = _extra_types()
    if ros1:  # the noetic store has no tf2_msgs
        types.update(get_types_from_msg(_TF_MESSAGE_ROS1, TF_MESSAGE))
    store.register({name: t for name, t in types.items() if name not in store.fielddefs})
    return store


def header_stamp_ns(header) -> int:
    """A ``std_msgs/Header`` stamp (``sec``, ``nanosec``) in integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def raw_header_stamp_ns(raw: bytes, *, cdr: bool) -> int | None:
    """The header stamp of a serialised message that starts with a ``std_msgs/Header``.

    Read straight from the bytes (no deserialisation), in integer nanoseconds: ROS 1 puts
    ``uint32 seq, uint32 secs, uint32 nsecs`` first; CDR (ROS 2) a 4-byte encapsulation header,
    then ``int32 sec, uint32 nanosec`` in its byte order. Returns None for bytes too short or an
    encapsulation this reader does not know (the caller then deserialises).
    """
    if cdr:
        if len(raw) < 12 or raw[0] != 0 or raw[1] not in (0, 1):
            return None
        order = "<" if raw[1] == 1 else ">"
        sec = int(np.frombuffer(raw[4:8], dtype=f"{order}i4")[0])
        nanosec = int(np.frombuffer(raw[8:12], dtype=f"{order}u4")[0])
    else:
        if len(raw) < 12:
            return None
        _, sec, nanosec = (int(v) for v in np.frombuffer(raw[:12], dtype="<u4"))
    return sec * 1_000_000_000 + nanosec


# ----------------------------------------------------------------------------------------------
# Decoding


def parse_livox_raw(raw: bytes, *, cdr: bool) -> tuple[int, dict[str, np.ndarray]] | None:
    """Livox CustomMsg fields straight from ROS 1 or little-endian CDR bytes.

    Returns None for an encoding this fast path does not handle (the caller then deserialises).
    Layout: Header, uint64 timebase, uint32 point_num, uint8 lidar_id, uint8[3] rsvd, then the
    points (uint32 offset_time, float32 x y z, uint8 reflectivity tag line): 19 bytes each in
    ROS 1, 20 in CDR (aligned to 4).
    """
    u32 = np.dtype("<u4")
    try:
        if cdr:
            if raw[:2] != b"\x00\x01":  # plain CDR, little endian
                return None
            body, base = raw[4:], 4
            sec, nanosec = np.frombuffer(body[:8], dtype=u32)
            pos = 8
            (name_len,) = np.frombuffer(body[pos : pos + 4], dtype=u32)
            pos += 4 + int(name_len)
            pos = (pos + 7) // 8 * 8  # uint64 timebase
            pos += 8 + 4 + 1 + 3
            pos = (pos + 3) // 4 * 4  # sequence length
            stride = 20
        else:
            body, base = raw, 0
            _, sec, nanosec = np.frombuffer(body[:12], dtype=u32)
            (name_len,) = np.frombuffer(body[12:16], dtype=u32)
            pos = 16 + int(name_len) + 8 + 4 + 1 + 3
            stride = 19
        (count,) = np.frombuffer(body[pos : pos + 4], dtype=u32)
        count = int(count)
        pos += 4
        start = base + pos
    except ValueError:  # too short for the fixed part
        return None
    if count and len(raw) < start + stride * (count - 1) + 19:
        return None
    dtype = np.dtype(
        {
            "names": list(LIVOX_FIELDS),
            "formats": list(_LIVOX_FORMATS),
            "offsets": list(_LIVOX_OFFSETS),
            "itemsize": stride,
        }
    )
    buffer = raw[start : start + stride * count]
    if len(buffer) < stride * count:  # the last CDR point has no trailing padding
        buffer = buffer + bytes(stride * count - len(buffer))
    points = np.frombuffer(buffer, dtype=dtype, count=count)
    fields = native_columns(points, _LIVOX_ORDER)
    return int(sec) * 1_000_000_000 + int(nanosec), fields


def livox_fields_from_msg(msg) -> tuple[int, dict[str, np.ndarray]]:
    """Livox CustomMsg ``(stamp_ns, fields)`` from a deserialised message.

    The same fields, dtypes and order as :func:`parse_livox_raw`; the slow, sure way for the
    encodings that the byte-level path does not handle.
    """
    points = msg.points
    fields = {
        name: np.array([getattr(p, name) for p in points], dtype=np.dtype(_LIVOX_FORMATS[k]))
        for k, name in enumerate(LIVOX_FIELDS)
    }
    fields = {name: fields[name] for name in _LIVOX_ORDER}
    return header_stamp_ns(msg.header), fields


_IMAGE_LAYOUTS = {  # encoding -> (channels, dtype, channel order)
    "mono8": (1, np.uint8, "grey"),
    "8uc1": (1, np.uint8, "grey"),
    "mono16": (1, np.uint16, "grey"),
    "16uc1": (1, np.uint16, "grey"),
    "bgr8": (3, np.uint8, "bgr"),
    "8uc3": (3, np.uint8, "bgr"),
    "rgb8": (3, np.uint8, "rgb"),
    "bgra8": (4, np.uint8, "bgra"),
    "8uc4": (4, np.uint8, "bgra"),
    "rgba8": (4, np.uint8, "rgba"),
    "bgr16": (3, np.uint16, "bgr"),
    "16uc3": (3, np.uint16, "bgr"),
    "rgb16": (3, np.uint16, "rgb"),
    "bgra16": (4, np.uint16, "bgra"),
    "16uc4": (4, np.uint16, "bgra"),
    "rgba16": (4, np.uint16, "rgba"),
    "bayer_rggb8": (1, np.uint8, "RGGB"),
    "bayer_bggr8": (1, np.uint8, "BGGR"),
    "bayer_gbrg8": (1, np.uint8, "GBRG"),
    "bayer_grbg8": (1, np.uint8, "GRBG"),
    "bayer_rggb16": (1, np.uint16, "RGGB"),
    "bayer_bggr16": (1, np.uint16, "BGGR"),
    "bayer_gbrg16": (1, np.uint16, "GBRG"),
    "bayer_grbg16": (1, np.uint16, "GRBG"),
    "yuv422": (2, np.uint8, "UYVY"),
    "uyvy": (2, np.uint8, "UYVY"),
    "yuv422_yuy2": (2, np.uint8, "YUY2"),
    "yuyv": (2, np.uint8, "YUY2"),
}
# OpenCV's legacy Bayer names count from the second row and column (RGGB is "BG")
_BAYER_LEGACY = {"RGGB": "BG", "BGGR": "RG", "GBRG": "GR", "GRBG": "GB"}


def _bayer_code(pattern: str, target: str) -> int:
    import cv2

    name = f"COLOR_Bayer{pattern}2{target}"
    if hasattr(cv2, name):
        return getattr(cv2, name)
    return getattr(cv2, f"COLOR_Bayer{_BAYER_LEGACY[pattern]}2{target}")


def _convert_channels(pixels: np.ndarray, order: str, *, grey: bool) -> np.ndarray:
    """Pixels in ``order`` (grey, rgb, bgr, rgba, bgra, Bayer, UYVY/YUY2) -> grey or RGB."""
    import cv2

    target = "GRAY" if grey else "RGB"
    if order == "grey":
        return pixels
    if order in ("rgb", "bgr", "rgba", "bgra"):
        if order == "rgb" and not grey:
            return pixels
        code = getattr(cv2, f"COLOR_{order.upper()}2{target}")
        return cv2.cvtColor(pixels, code)
    if order in _BAYER_LEGACY:
        return cv2.cvtColor(pixels, _bayer_code(order, target))
    return cv2.cvtColor(pixels, getattr(cv2, f"COLOR_YUV2{target}_{order}"))


def decode_image(msg, *, grey: bool = True, source=None) -> np.ndarray:
    """Decode a ``sensor_msgs/Image`` into an array.

    Parameters
    ----------
    msg : sensor_msgs/Image (any object with its attributes)
        ``height``, ``width``, ``encoding``, ``is_bigendian``, ``step``, ``data``.
    grey : bool
        Convert colour to grey (OpenCV weights); otherwise colour comes back RGB.
    source : str, optional
        Named in error messages.

    Returns
    -------
    ndarray of shape (H, W) or (H, W, 3), uint8 or uint16
        Row padding (``step``) removed, 16-bit data in native byte order.

    Raises
    ------
    InputError
        Unknown encoding, data shorter than ``height x step``, or a YUV 4:2:2 image of odd width.
    """
    encoding = str(msg.encoding).lower()
    if encoding not in _IMAGE_LAYOUTS:
        raise InputError(
            f"unsupported image encoding '{msg.encoding}'; supported: "
            f"{', '.join(sorted(_IMAGE_LAYOUTS))}",
            path=source,
        )
    channels, dtype, order = _IMAGE_LAYOUTS[encoding]
    dtype = np.dtype(dtype).newbyteorder(">" if msg.is_bigendian else "<")
    height, width, step = int(msg.height), int(msg.width), int(msg.step)
    row_bytes = width * channels * dtype.itemsize
    step = step or row_bytes
    data = buffer_array(msg.data).reshape(-1).view(np.uint8)
    if step < row_bytes or data.size < (height - 1) * step + row_bytes or height * width == 0:
        raise InputError(
            f"{encoding} image data of {data.size} bytes does not hold {height} x {width} "
            f"pixels with step {msg.step}",
            path=source,
        )
    if order in ("UYVY", "YUY2") and width % 2:
        raise InputError(f"{encoding} image has an odd width {width}", path=source)
    rows = np.lib.stride_tricks.as_strided(
        data, shape=(height, row_bytes), strides=(step, 1), writeable=False
    )
    pixels = np.ascontiguousarray(rows).view(dtype).astype(dtype.newbyteorder("="), copy=False)
    pixels = (
        pixels.reshape(height, width, channels) if channels > 1 else pixels.reshape(height, width)
    )
    if order in ("UYVY", "YUY2"):
        pixels = np.ascontiguousarray(pixels)
    return np.ascontiguousarray(_convert_channels(pixels, order, grey=grey))


def decode_compressed_image(msg, *, grey: bool = True, source=None) -> np.ndarray:
    """Decode a ``sensor_msgs/CompressedImage`` (JPEG, PNG, ...) with OpenCV.

    Returns
    -------
    ndarray of shape (H, W) or (H, W, 3), uint8 or uint16
        Grey, or RGB when ``grey=False`` and the image is colour.
    """
    import cv2

    from nbcalib.io.image import _from_bgr

    data = np.ascontiguousarray(buffer_array(msg.data), dtype=np.uint8)
    try:
        image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error:  # a corrupt header OpenCV refuses (sizes beyond its limits)
        image = None
    if image is None:
        raise InputError(f"cannot decode compressed image (format '{msg.format}')", path=source)
    if image.dtype not in (np.uint8, np.uint16):
        raise InputError(f"compressed image has unsupported pixel type {image.dtype}", path=source)
    return _from_bgr(image, grey=grey)


def camera_from_camera_info_msg(msg, *, source=None) -> CameraModel:
    """A :class:`~nbcalib.camera.CameraModel` from a ``sensor_msgs/CameraInfo`` message.

    Wraps :func:`nbcalib.camera.camera_from_camera_info` (``fx = K[0], fy = K[4], cx = K[2],
    cy = K[5]`` as the reference; nbcalib's extensions as in the module docstring) and turns its
    ``ValueError`` into an :class:`~nbcalib.errors.InputError` naming ``source``.
    """
    from nbcalib.camera import camera_from_camera_info

    try:
        return camera_from_camera_info(msg)
    except ValueError as exc:
        raise InputError(f"bad CameraInfo ({msg.distortion_model}): {exc}", path=source) from None
