"""ROS 1 and ROS 2 bags without a ROS installation (through the pure-Python ``rosbags`` package).

Reading: :func:`open_bag` (or the one-shot helpers :func:`read_pointclouds`, :func:`read_images`,
:func:`read_camera_info`, :func:`read_tf_static`, :func:`list_topics`) opens a ROS 1 ``.bag``
file, a ROS 2 bag folder (sqlite3 or mcap), or a single ``.db3`` / ``.mcap`` file, and decodes
messages into arrays:

- ``sensor_msgs/PointCloud2`` and Livox ``CustomMsg`` (``livox_ros_driver2`` and
  ``livox_ros_driver``) -> :class:`~nbcalib.io.pointcloud.PointCloud` (reference rules for the
  intensity channel and per-point times; Livox: ``reflectivity`` is the intensity and
  ``offset_time`` [ns] the per-point time);
- ``sensor_msgs/Image`` (mono8/16, rgb8/16, bgr8/16, rgba/bgra, 8UC1..16UC4, bayer_*, yuv422) and
  ``sensor_msgs/CompressedImage`` -> uint8/uint16 arrays, grey or RGB;
- ``sensor_msgs/CameraInfo`` -> :class:`~nbcalib.camera.CameraModel`;
- ``tf2_msgs/TFMessage`` on ``/tf_static`` -> ``(parent, child, T_parent_child)``.

Stamps are the message header's, in integer nanoseconds (the bag's receive time when the header
stamp is 0). When ``topic`` is None the only topic of the needed type is used; several or none
raise :class:`~nbcalib.errors.InputError` naming the bag and the candidates.

Writing: :class:`BagWriter` writes the same messages as ROS 1 (``bag1``), ROS 2 sqlite3
(``bag2``) or ROS 2 mcap (``mcap``), into a temporary name that is renamed into place on a clean
close.

CameraInfo for models ROS cannot name (an nbcalib extension; the mapping is
:func:`nbcalib.camera.camera_to_camera_info` / :func:`nbcalib.camera.camera_from_camera_info`):
``distortion_model`` is the nbcalib model name and ``D`` its distortion: ``atan``:
``D = [omega]``; ``omnidir``: ``D = [xi, k1, k2, p1, p2]`` (xi first); ``equirectangular``:
``D = []`` (the intrinsics are the image size). ``pinhole`` is written as ``plumb_bob`` with zero
distortion and ``fisheye`` as ``equidistant``. The reference toolbox takes ``distortion_model`` as
its model name and ``K`` as fx, fy, cx, cy, so it reads all of these except omnidir's ``xi``.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError, require
from nbcalib.io.pointcloud import PointCloud, pointcloud_from_fields

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel

POINTCLOUD2 = "sensor_msgs/msg/PointCloud2"
IMAGE = "sensor_msgs/msg/Image"
COMPRESSED_IMAGE = "sensor_msgs/msg/CompressedImage"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
LIVOX_CUSTOM = ("livox_ros_driver2/msg/CustomMsg", "livox_ros_driver/msg/CustomMsg")

#: Message types accepted for each kind of data.
MESSAGE_KINDS = {
    "point cloud": (POINTCLOUD2, *LIVOX_CUSTOM),
    "image": (IMAGE, COMPRESSED_IMAGE),
    "camera info": (CAMERA_INFO,),
    "tf": (TF_MESSAGE,),
}

BAG_FORMATS = ("bag1", "bag2", "mcap")

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

_LIVOX_FIELDS = ("offset_time", "x", "y", "z", "reflectivity", "tag", "line")
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


def _typestore(ros1: bool):
    """Type store (rosbags) for writing (and for ROS 2 bags without embedded definitions)."""
    require("rosbags", "bags")
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types = _extra_types()
    if ros1:  # the noetic store has no tf2_msgs
        types.update(get_types_from_msg(_TF_MESSAGE_ROS1, TF_MESSAGE))
    store.register({name: t for name, t in types.items() if name not in store.fielddefs})
    return store


def _stamp_ns(header) -> int:
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


# ----------------------------------------------------------------------------------------------
# Reading


class Bag:
    """An open ROS 1 or ROS 2 bag; use :func:`open_bag` (a context manager).

    Attributes
    ----------
    path : pathlib.Path
        The bag file or folder.
    topics : dict of str to str
        Topic name -> message type (``pkg/msg/Type``), sorted by name.
    message_counts : dict of str to int
        Topic name -> number of messages.
    """

    def __init__(self, path):
        require("rosbags", "bags")
        from rosbags.highlevel import AnyReader

        self.path = Path(path)
        bag_path = _resolve_bag_path(self.path)
        try:
            self._reader = AnyReader([bag_path], default_typestore=_typestore(ros1=False))
            self._reader.open()
        except FileNotFoundError as exc:
            raise InputError(f"cannot open as a ROS bag: {exc}", path=self.path) from None
        except Exception as exc:  # rosbags, sqlite3, yaml and mcap errors alike
            raise InputError(
                f"cannot open as a ROS bag ({type(exc).__name__}: {exc})", path=self.path
            ) from None
        self._add_missing_types()
        self.topics = {
            name: info.msgtype or "(mixed types)"
            for name, info in sorted(self._reader.topics.items())
        }
        self.message_counts = {
            name: int(info.msgcount) for name, info in sorted(self._reader.topics.items())
        }

    def _add_missing_types(self) -> None:
        """Register known types (Livox, ROS 2 Humble) that the bag did not define."""
        store = self._reader.typestore
        missing = {c.msgtype for c in self._reader.connections} - set(store.fielddefs)
        if missing:
            known = _typestore(ros1=not self._reader.is2).fielddefs
            store.register({name: t for name, t in known.items() if name not in store.fielddefs})

    def close(self) -> None:
        """Close the bag (idempotent)."""
        if getattr(self, "_reader", None) is not None and self._reader.stack is not None:
            self._reader.close()

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Bag({str(self.path)!r}, topics={self.topics})"

    def select_topic(self, kind: str, topic: str | None = None) -> str:
        """The topic to read for ``kind`` (a key of :data:`MESSAGE_KINDS`).

        Parameters
        ----------
        kind : str
            ``"point cloud"``, ``"image"``, ``"camera info"`` or ``"tf"``.
        topic : str, optional
            Given topic: checked to exist and to carry a type of that kind. None: the only topic
            of that kind.

        Raises
        ------
        InputError
            No topic of that kind (names the types the bag has), several (lists them), or a
            given topic that does not exist or has another type.
        """
        types = MESSAGE_KINDS[kind]
        candidates = [t for t, msgtype in self.topics.items() if msgtype in types]
        if topic is not None:
            if topic not in self.topics:
                listed = ", ".join(candidates) or "none"
                raise InputError(
                    f"no topic '{topic}' in the bag; {kind} topics: {listed}", path=self.path
                )
            if self.topics[topic] not in types:
                raise InputError(
                    f"topic '{topic}' has type {self.topics[topic]}, not a {kind} type "
                    f"({', '.join(types)})",
                    path=self.path,
                )
            return topic
        if not candidates:
            have = ", ".join(f"{t} ({m})" for t, m in self.topics.items()) or "no topics"
            raise InputError(
                f"no {kind} topic ({', '.join(types)}); the bag has: {have}", path=self.path
            )
        if len(candidates) > 1:
            listed = ", ".join(f"{t} ({self.topics[t]})" for t in candidates)
            raise InputError(
                f"several {kind} topics: {listed}; choose one with the topic option",
                path=self.path,
            )
        return candidates[0]

    def raw_messages(self, topic: str) -> Iterator[tuple[int, str, bytes]]:
        """Yield ``(receive_time_ns, msgtype, raw_bytes)`` of one topic, in time order."""
        connections = [c for c in self._reader.connections if c.topic == topic]
        if not connections:
            raise InputError(f"no topic '{topic}' in the bag", path=self.path)
        for connection, log_time, raw in self._reader.messages(connections=connections):
            yield int(log_time), connection.msgtype, raw

    def messages(self, topic: str) -> Iterator[tuple[int, object]]:
        """Yield ``(stamp_ns, message)`` of one topic, deserialised by rosbags."""
        for log_time, msgtype, raw in self.raw_messages(topic):
            msg = self._deserialize(raw, msgtype, topic)
            header = getattr(msg, "header", None)
            stamp = _stamp_ns(header) if header is not None else 0
            yield (stamp or log_time), msg

    def _deserialize(self, raw: bytes, msgtype: str, topic: str):
        try:
            return self._reader.deserialize(raw, msgtype)
        except Exception as exc:
            raise InputError(
                f"cannot decode a {msgtype} message on {topic} ({type(exc).__name__}: {exc})",
                path=self.path,
            ) from None

    def pointclouds(
        self,
        topic: str | None = None,
        *,
        intensity_channel: str | None = "auto",
        time_field: str | None = "auto",
    ) -> Iterator[tuple[int, PointCloud]]:
        """Yield ``(stamp_ns, PointCloud)`` for every message of a point cloud topic.

        Parameters
        ----------
        topic : str, optional
            PointCloud2 or Livox CustomMsg topic; None picks the only one.
        intensity_channel : str or None
            ``"auto"`` picks ``reflectivity`` over ``intensity``; a name must exist (the error lists
            the fields); None for no intensity.
        time_field : str or None
            ``"auto"`` picks the first of ``t``, ``time``, ``time_stamp``, ``timestamp``
            (``offset_time`` for Livox); a name; or None.

        Yields
        ------
        stamp_ns : int
            Header stamp, nanoseconds.
        cloud : PointCloud
            Points in the LiDAR frame (metres), intensity as stored, times in seconds relative
            to the scan.
        """
        from nbcalib.io.pointcloud2 import pointcloud2_to_fields

        topic = self.select_topic("point cloud", topic)
        source = f"{self.path} {topic}"
        for log_time, msgtype, raw in self.raw_messages(topic):
            if msgtype in LIVOX_CUSTOM:
                stamp, fields = self._livox_fields(raw, msgtype, topic)
                times = "offset_time" if time_field == "auto" else time_field
            else:
                msg = self._deserialize(raw, msgtype, topic)
                stamp = _stamp_ns(msg.header)
                fields = pointcloud2_to_fields(msg, source=source)
                times = time_field
            cloud = pointcloud_from_fields(
                fields, intensity_channel=intensity_channel, time_field=times, source=source
            )
            yield (stamp or log_time), cloud

    def _livox_fields(self, raw: bytes, msgtype: str, topic: str) -> tuple[int, dict]:
        """Livox CustomMsg -> (stamp_ns, fields), straight from the bytes when possible."""
        parsed = _parse_livox_raw(bytes(raw), cdr=self._reader.is2)
        if parsed is not None:
            return parsed
        msg = self._deserialize(raw, msgtype, topic)  # exotic encodings: the slow, sure way
        points = msg.points
        fields = {
            name: np.array([getattr(p, name) for p in points], dtype=np.dtype(_LIVOX_FORMATS[k]))
            for k, name in enumerate(_LIVOX_FIELDS)
        }
        fields = {name: fields[name] for name in _LIVOX_ORDER}
        return _stamp_ns(msg.header), fields

    def images(
        self, topic: str | None = None, *, grey: bool = True
    ) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(stamp_ns, image)`` for every message of an Image or CompressedImage topic.

        Parameters
        ----------
        topic : str, optional
            None picks the only image topic.
        grey : bool
            Convert colour to grey with OpenCV's weights (as ``cv_bridge`` to ``mono8``).

        Yields
        ------
        stamp_ns : int
            Header stamp, nanoseconds.
        image : ndarray of shape (H, W) or (H, W, 3), uint8 or uint16
            As stored (8 or 16 bit); colour in RGB order when ``grey=False``.
        """
        topic = self.select_topic("image", topic)
        source = f"{self.path} {topic}"
        for stamp, msg in self.messages(topic):
            if self.topics[topic] == COMPRESSED_IMAGE:
                yield stamp, decode_compressed_image(msg, grey=grey, source=source)
            else:
                yield stamp, decode_image(msg, grey=grey, source=source)

    def camera_info(self, topic: str | None = None) -> CameraModel:
        """The camera of the first CameraInfo message of a topic (None picks the only one).

        ``fx, fy, cx, cy`` come from ``K``; the model from ``distortion_model`` (``plumb_bob``,
        ``rational_polynomial``, ``equidistant``, and nbcalib's extensions, module docstring).
        """
        topic = self.select_topic("camera info", topic)
        for _, msg in self.messages(topic):
            return camera_from_camera_info_msg(msg, source=f"{self.path} {topic}")
        raise InputError(f"topic {topic} has no messages", path=self.path)

    def tf_static(self, topic: str = "/tf_static") -> list[tuple[str, str, np.ndarray]]:
        """All transforms on ``/tf_static``: ``(parent_frame, child_frame, T_parent_child)``.

        ``T_parent_child`` (4 x 4, float64) maps child-frame coordinates into the parent frame,
        ``p_parent = T_parent_child @ p_child`` (ROS's transform from ``header.frame_id`` to
        ``child_frame_id``). An empty list when the bag has no such topic.
        """
        from nbcalib.transforms import quat_xyzw_to_matrix

        if topic not in self.topics:
            return []
        self.select_topic("tf", topic)
        transforms = []
        for _, msg in self.messages(topic):
            for tf in msg.transforms:
                q, t = tf.transform.rotation, tf.transform.translation
                T = np.eye(4)
                T[:3, :3] = quat_xyzw_to_matrix([q.x, q.y, q.z, q.w])
                T[:3, 3] = [t.x, t.y, t.z]
                transforms.append((tf.header.frame_id, tf.child_frame_id, T))
        return transforms


def _resolve_bag_path(path: Path) -> Path:
    if not path.exists():
        raise InputError("bag not found", path=path)
    if path.is_dir() and not (path / "metadata.yaml").exists():
        storages = sorted([*path.glob("*.db3"), *path.glob("*.mcap")])
        if len(storages) == 1:
            return storages[0]
        raise InputError(
            "folder is not a ROS 2 bag (no metadata.yaml"
            + (f", {len(storages)} storage files)" if storages else ")"),
            path=path,
        )
    if path.is_file() and path.suffix.lower() not in (".bag", ".db3", ".mcap"):
        raise InputError(
            f"unknown bag suffix '{path.suffix}'; expected a ROS 1 .bag file, a ROS 2 bag "
            "folder, or a .db3 / .mcap file",
            path=path,
        )
    return path


def open_bag(path) -> Bag:
    """Open a ROS 1 ``.bag``, a ROS 2 bag folder, or a ``.db3`` / ``.mcap`` file.

    Use as a context manager: ``with open_bag(path) as bag: bag.topics``.

    Raises
    ------
    InputError
        Missing path or not a bag; the message names it.
    """
    return Bag(path)


def list_topics(bag_path) -> dict[str, str]:
    """Topic name -> message type (``pkg/msg/Type``) of a bag."""
    with open_bag(bag_path) as bag:
        return dict(bag.topics)


def read_pointclouds(
    bag_path,
    topic: str | None = None,
    *,
    intensity_channel: str | None = "auto",
    time_field: str | None = "auto",
) -> Iterator[tuple[int, PointCloud]]:
    """Yield ``(stamp_ns, PointCloud)`` of a bag's point cloud topic (:meth:`Bag.pointclouds`)."""
    with open_bag(bag_path) as bag:
        yield from bag.pointclouds(
            topic, intensity_channel=intensity_channel, time_field=time_field
        )


def read_images(
    bag_path, topic: str | None = None, *, grey: bool = True
) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(stamp_ns, image)`` from a bag's image topic; see :meth:`Bag.images`."""
    with open_bag(bag_path) as bag:
        yield from bag.images(topic, grey=grey)


def read_camera_info(bag_path, topic: str | None = None) -> CameraModel:
    """The camera of a bag's first CameraInfo message; see :meth:`Bag.camera_info`."""
    with open_bag(bag_path) as bag:
        return bag.camera_info(topic)


def read_tf_static(bag_path) -> list[tuple[str, str, np.ndarray]]:
    """``(parent_frame, child_frame, T_parent_child)`` of every ``/tf_static`` transform."""
    with open_bag(bag_path) as bag:
        return bag.tf_static()


# ----------------------------------------------------------------------------------------------
# Message decoding


def _parse_livox_raw(raw: bytes, *, cdr: bool) -> tuple[int, dict[str, np.ndarray]] | None:
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
            "names": list(_LIVOX_FIELDS),
            "formats": list(_LIVOX_FORMATS),
            "offsets": list(_LIVOX_OFFSETS),
            "itemsize": stride,
        }
    )
    buffer = raw[start : start + stride * count]
    if len(buffer) < stride * count:  # the last CDR point has no trailing padding
        buffer = buffer + bytes(stride * count - len(buffer))
    points = np.frombuffer(buffer, dtype=dtype, count=count)
    fields = {
        name: np.ascontiguousarray(points[name], dtype=points[name].dtype.newbyteorder("="))
        for name in _LIVOX_ORDER
    }
    return int(sec) * 1_000_000_000 + int(nanosec), fields


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
        Unknown encoding or data shorter than ``height x step``.
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
    data = (
        np.frombuffer(msg.data, dtype=np.uint8)
        if not isinstance(msg.data, np.ndarray)
        else msg.data
    )
    data = data.reshape(-1).view(np.uint8)
    if step < row_bytes or data.size < (height - 1) * step + row_bytes or height * width == 0:
        raise InputError(
            f"{encoding} image data of {data.size} bytes does not hold {height} x {width} "
            f"pixels with step {msg.step}",
            path=source,
        )
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

    data = (
        np.frombuffer(msg.data, dtype=np.uint8)
        if not isinstance(msg.data, np.ndarray)
        else msg.data
    )
    image = cv2.imdecode(np.ascontiguousarray(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
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


# ----------------------------------------------------------------------------------------------
# Writing


class BagWriter:
    """Write point clouds, images, CameraInfo and static transforms as a ROS bag.

    Parameters
    ----------
    path : str or os.PathLike
        ``bag1``: the ``.bag`` file; ``bag2`` / ``mcap``: the bag folder (the storage file inside
        is named after it, as ``ros2 bag record`` does).
    fmt : {"bag1", "bag2", "mcap"}
        ROS 1 bag v2.0, ROS 2 sqlite3, or ROS 2 mcap (rosbag2 metadata version 8).
    overwrite : bool
        Replace an existing bag at ``path`` (on a clean close only).

    Notes
    -----
    A context manager: ``with BagWriter(path, "mcap") as bag: bag.write_image(...)``. Everything
    is written under a temporary name and renamed to ``path`` when the block ends without an
    exception; after an exception nothing is left behind. Message stamps (header and bag time)
    are integer nanoseconds.
    """

    def __init__(self, path, fmt: str, *, overwrite: bool = False):
        if fmt not in BAG_FORMATS:
            raise ValueError(f"fmt must be one of {BAG_FORMATS}, got {fmt!r}")
        self.path = Path(path)
        self.fmt = fmt
        self.overwrite = overwrite
        if fmt == "bag1" and self.path.suffix != ".bag":
            raise ValueError(f"a ROS 1 bag file must end in .bag, got {self.path.name!r}")
        if self.path.exists() and not overwrite:
            raise InputError("exists already; choose another name or overwrite", path=self.path)
        self._ros1 = fmt == "bag1"
        self._store = _typestore(ros1=self._ros1)
        self._writer = None
        self._tmpdir: Path | None = None
        self._connections: dict[str, tuple[str, object]] = {}

    # -- life cycle

    def open(self) -> BagWriter:
        """Start writing (called by ``with``)."""
        from rosbags.rosbag1 import Writer as Writer1
        from rosbags.rosbag2 import StoragePlugin
        from rosbags.rosbag2 import Writer as Writer2

        if self._writer is not None:
            raise RuntimeError("BagWriter is already open")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._tmpdir = Path(tempfile.mkdtemp(dir=self.path.parent, prefix=f".{self.path.name}."))
        target = self._tmpdir / self.path.name
        if self._ros1:
            self._writer = Writer1(target)
        else:
            plugin = StoragePlugin.MCAP if self.fmt == "mcap" else StoragePlugin.SQLITE3
            self._writer = Writer2(target, version=8, storage_plugin=plugin)
        self._writer.open()
        return self

    def close(self) -> None:
        """Finish the bag and move it to ``path``."""
        if self._writer is None:
            return
        writer, self._writer = self._writer, None
        writer.close()
        target = self._tmpdir / self.path.name
        if self.path.exists() and self.overwrite:
            if self.path.is_dir():
                shutil.rmtree(self.path)
            else:
                self.path.unlink()
        os.replace(target, self.path)
        shutil.rmtree(self._tmpdir, ignore_errors=True)
        self._tmpdir = None

    def abort(self) -> None:
        """Drop everything written so far."""
        writer, self._writer = self._writer, None
        if writer is not None:
            try:
                writer.close()
            except Exception:  # the partial bag is deleted below anyway
                pass
        if self._tmpdir is not None:
            shutil.rmtree(self._tmpdir, ignore_errors=True)
            self._tmpdir = None

    def __enter__(self) -> BagWriter:
        return self.open()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()

    # -- helpers

    def _msg(self, msgtype: str, **kwargs):
        return self._store.types[msgtype](**kwargs)

    def _header(self, stamp_ns: int, frame_id: str):
        stamp_ns = int(stamp_ns)
        if stamp_ns < 0:
            raise ValueError(f"stamp_ns must be >= 0, got {stamp_ns}")
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        stamp = self._msg("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)
        if self._ros1:
            return self._msg("std_msgs/msg/Header", seq=0, stamp=stamp, frame_id=frame_id)
        return self._msg("std_msgs/msg/Header", stamp=stamp, frame_id=frame_id)

    def _write(self, topic: str, msgtype: str, stamp_ns: int, msg) -> None:
        if self._writer is None:
            raise RuntimeError("BagWriter is not open; use it in a with block or call open()")
        if topic in self._connections:
            known_type, connection = self._connections[topic]
            if known_type != msgtype:
                raise ValueError(f"topic {topic} already carries {known_type}, not {msgtype}")
        else:
            extra = {"latching": 1} if self._ros1 and topic == "/tf_static" else {}
            connection = self._writer.add_connection(topic, msgtype, typestore=self._store, **extra)
            self._connections[topic] = (msgtype, connection)
        if self._ros1:
            raw = self._store.serialize_ros1(msg, msgtype)
        else:
            raw = self._store.serialize_cdr(msg, msgtype)
        self._writer.write(connection, int(stamp_ns), raw)

    # -- messages

    def write_pointcloud(
        self, topic: str, stamp_ns: int, fields: Mapping[str, np.ndarray], frame_id: str
    ) -> None:
        """Write a ``sensor_msgs/PointCloud2`` (``height`` 1, little endian, no padding).

        Parameters
        ----------
        topic : str
        stamp_ns : int
            Header stamp and bag time, nanoseconds.
        fields : mapping of str to ndarray of shape (N,) or (N, count)
            Fields in message order with their dtypes (int8..uint32, float32, float64), e.g.
            ``x, y, z`` float32 (metres, LiDAR frame), ``intensity`` float32, ``t`` float32 (s)
            or uint32 (ns), ``ring`` uint16.
        frame_id : str
            The LiDAR frame.
        """
        from nbcalib.io.pointcloud2 import pack_pointcloud2

        specs, point_step, data = pack_pointcloud2(fields)
        n = data.size // point_step if point_step else 0
        point_fields = [
            self._msg(
                "sensor_msgs/msg/PointField",
                name=s.name,
                offset=s.offset,
                datatype=s.datatype,
                count=s.count,
            )
            for s in specs
        ]
        xyz = [fields[c] for c in "xyz" if c in fields]
        is_dense = bool(all(np.isfinite(np.asarray(v)).all() for v in xyz))
        msg = self._msg(
            POINTCLOUD2,
            header=self._header(stamp_ns, frame_id),
            height=1,
            width=n,
            fields=point_fields,
            is_bigendian=False,
            point_step=point_step,
            row_step=n * point_step,
            data=data,
            is_dense=is_dense,
        )
        self._write(topic, POINTCLOUD2, stamp_ns, msg)

    def write_livox(
        self,
        topic: str,
        stamp_ns: int,
        fields: Mapping[str, np.ndarray],
        frame_id: str,
        *,
        package: str = "livox_ros_driver2",
        lidar_id: int = 0,
    ) -> None:
        """Write a Livox ``CustomMsg`` (``livox_ros_driver2`` or ``livox_ros_driver``).

        Parameters
        ----------
        fields : mapping of str to ndarray of shape (N,)
            ``x, y, z`` (metres), ``reflectivity`` (uint8), ``offset_time`` (nanoseconds after
            ``stamp_ns``, uint32); optional ``tag`` and ``line`` (uint8, default 0).
        """
        if package not in ("livox_ros_driver2", "livox_ros_driver"):
            raise ValueError(
                f"package must be livox_ros_driver2 or livox_ros_driver, got {package!r}"
            )
        msgtype = f"{package}/msg/CustomMsg"
        n = len(fields["x"])
        zeros = np.zeros(n, dtype=np.uint8)
        columns = {
            "offset_time": np.asarray(fields["offset_time"], dtype=np.uint32),
            "x": np.asarray(fields["x"], dtype=np.float32),
            "y": np.asarray(fields["y"], dtype=np.float32),
            "z": np.asarray(fields["z"], dtype=np.float32),
            "reflectivity": np.asarray(fields["reflectivity"], dtype=np.uint8),
            "tag": np.asarray(fields.get("tag", zeros), dtype=np.uint8),
            "line": np.asarray(fields.get("line", zeros), dtype=np.uint8),
        }
        point_type = self._store.types[f"{package}/msg/CustomPoint"]
        rows = zip(*(columns[name].tolist() for name in _LIVOX_FIELDS))
        points = [point_type(*row) for row in rows]
        msg = self._msg(
            msgtype,
            header=self._header(stamp_ns, frame_id),
            timebase=int(stamp_ns),
            point_num=n,
            lidar_id=lidar_id,
            rsvd=np.zeros(3, dtype=np.uint8),
            points=points,
        )
        self._write(topic, msgtype, stamp_ns, msg)

    def write_image(self, topic: str, stamp_ns: int, image: np.ndarray, frame_id: str) -> None:
        """Write a ``sensor_msgs/Image``.

        Parameters
        ----------
        image : ndarray of shape (H, W) or (H, W, 3)
            (H, W) uint8 -> ``mono8``, (H, W) uint16 -> ``mono16``, (H, W, 3) uint8 -> ``rgb8``
            (RGB order in memory, nbcalib's convention).
        frame_id : str
            The camera (optical) frame.
        """
        image = np.ascontiguousarray(image)
        if image.ndim == 2 and image.dtype == np.uint8:
            encoding = "mono8"
        elif image.ndim == 2 and image.dtype == np.uint16:
            encoding = "mono16"
        elif image.ndim == 3 and image.shape[2] == 3 and image.dtype == np.uint8:
            encoding = "rgb8"
        else:
            raise ValueError(
                f"expected an (H, W) uint8/uint16 or (H, W, 3) uint8 image, got {image.shape} "
                f"{image.dtype}"
            )
        height, width = image.shape[:2]
        data = image.astype(image.dtype.newbyteorder("<"), copy=False).view(np.uint8).reshape(-1)
        msg = self._msg(
            IMAGE,
            header=self._header(stamp_ns, frame_id),
            height=height,
            width=width,
            encoding=encoding,
            is_bigendian=0,
            step=data.size // height if height else 0,
            data=data,
        )
        self._write(topic, IMAGE, stamp_ns, msg)

    def write_compressed_image(
        self, topic: str, stamp_ns: int, image: np.ndarray, frame_id: str, *, fmt: str = "png"
    ) -> None:
        """Write a ``sensor_msgs/CompressedImage`` (``fmt`` ``"png"`` or ``"jpeg"``).

        Parameters
        ----------
        image : ndarray of shape (H, W) or (H, W, 3), uint8 (or uint16 for PNG)
            Grey or RGB (nbcalib's order; stored as OpenCV's BGR, as ``image_transport`` does).
        """
        import cv2

        if fmt not in ("png", "jpeg"):
            raise ValueError(f"fmt must be 'png' or 'jpeg', got {fmt!r}")
        image = np.ascontiguousarray(image)
        if image.ndim == 3 and image.shape[2] == 3:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        elif image.ndim != 2:
            raise ValueError(f"expected an (H, W) or (H, W, 3) image, got {image.shape}")
        ok, encoded = cv2.imencode(".png" if fmt == "png" else ".jpg", image)
        if not ok:
            raise ValueError(f"OpenCV cannot encode a {image.dtype} {image.shape} image as {fmt}")
        colour = "bgr8" if image.ndim == 3 else ("mono16" if image.dtype == np.uint16 else "mono8")
        msg = self._msg(
            COMPRESSED_IMAGE,
            header=self._header(stamp_ns, frame_id),
            format=f"{colour}; {fmt} compressed {colour}",
            data=encoded.reshape(-1),
        )
        self._write(topic, COMPRESSED_IMAGE, stamp_ns, msg)

    def write_camera_info(
        self, topic: str, stamp_ns: int, camera: CameraModel, frame_id: str
    ) -> None:
        """Write a ``sensor_msgs/CameraInfo`` for ``camera`` (see the module docstring for names).

        Parameters
        ----------
        camera : CameraModel
            Any nbcalib camera; ``plumb_bob``, ``rational_polynomial`` and ``equidistant`` are
            ROS's names, the others are nbcalib extensions that nbcalib reads back.
        """
        from nbcalib.camera import camera_to_camera_info

        info = camera_to_camera_info(camera)
        names = dict.fromkeys(("D", "K", "R", "P"))
        fielddefs = {name for name, _ in self._store.fielddefs[CAMERA_INFO][1]}
        for key in names:
            names[key] = key if key in fielddefs else key.lower()
        roi = self._msg(
            "sensor_msgs/msg/RegionOfInterest",
            x_offset=0,
            y_offset=0,
            height=0,
            width=0,
            do_rectify=False,
        )
        msg = self._msg(
            CAMERA_INFO,
            header=self._header(stamp_ns, frame_id),
            height=int(camera.height),
            width=int(camera.width),
            distortion_model=info["distortion_model"],
            binning_x=0,
            binning_y=0,
            roi=roi,
            **{names[key]: np.asarray(info[key], dtype=np.float64) for key in names},
        )
        self._write(topic, CAMERA_INFO, stamp_ns, msg)

    def write_tf_static(
        self, stamp_ns: int, parent_frame: str, child_frame: str, T_parent_child: np.ndarray
    ) -> None:
        """Write one static transform as a ``tf2_msgs/TFMessage`` on ``/tf_static``.

        Parameters
        ----------
        T_parent_child : ndarray of shape (4, 4)
            Rigid transform with ``p_parent = T_parent_child @ p_child`` (metres); stored as
            translation and quaternion (x, y, z, w), ROS's transform from ``parent_frame``
            (header) to ``child_frame``.
        """
        from nbcalib.transforms import matrix_to_quat_xyzw

        T = np.asarray(T_parent_child, dtype=np.float64)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise ValueError(f"T_parent_child must be a finite 4 x 4 matrix, got shape {T.shape}")
        qx, qy, qz, qw = (float(c) for c in matrix_to_quat_xyzw(T[:3, :3]))
        transform = self._msg(
            "geometry_msgs/msg/Transform",
            translation=self._msg("geometry_msgs/msg/Vector3", x=T[0, 3], y=T[1, 3], z=T[2, 3]),
            rotation=self._msg("geometry_msgs/msg/Quaternion", x=qx, y=qy, z=qz, w=qw),
        )
        stamped = self._msg(
            "geometry_msgs/msg/TransformStamped",
            header=self._header(stamp_ns, parent_frame),
            child_frame_id=child_frame,
            transform=transform,
        )
        self._write("/tf_static", TF_MESSAGE, stamp_ns, self._msg(TF_MESSAGE, transforms=[stamped]))
