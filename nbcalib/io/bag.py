"""Reading ROS 1 and ROS 2 bags without a ROS installation (the pure-Python ``rosbags`` package).

:func:`open_bag` (or the one-shot helpers :func:`read_pointclouds`, :func:`read_images`,
:func:`read_camera_info`, :func:`read_tf_static`, :func:`list_topics`) opens a ROS 1 ``.bag``
file, a ROS 2 bag folder (sqlite3 or mcap), or a single ``.db3`` / ``.mcap`` file, and decodes
messages into arrays (the decoders are in :mod:`nbcalib.io.bag_messages` and
:mod:`nbcalib.io.pointcloud2`):

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

Writing bags: :class:`nbcalib.io.bag_writer.BagWriter`.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError, require
from nbcalib.io.bag_messages import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    IMAGE,
    LIVOX_CUSTOM,
    POINTCLOUD2,
    TF_MESSAGE,
    camera_from_camera_info_msg,
    decode_compressed_image,
    decode_image,
    header_stamp_ns,
    livox_fields_from_msg,
    parse_livox_raw,
    raw_header_stamp_ns,
    typestore,
)
from nbcalib.io.pointcloud import PointCloud, pointcloud_from_fields, warn_dropped_points

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel

#: Message types accepted for each kind of data.
MESSAGE_KINDS = {
    "point cloud": (POINTCLOUD2, *LIVOX_CUSTOM),
    "image": (IMAGE, COMPRESSED_IMAGE),
    "camera info": (CAMERA_INFO,),
    "tf": (TF_MESSAGE,),
}


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
        self._reader = None
        try:
            self._reader = AnyReader([bag_path], default_typestore=typestore(ros1=False))
            self._reader.open()
            self._add_missing_types()
            topics = sorted(self._reader.topics.items())  # damaged metadata: names not strings
            self.topics = {name: info.msgtype or "(mixed types)" for name, info in topics}
            self.message_counts = {name: int(info.msgcount) for name, info in topics}
        except FileNotFoundError as exc:
            raise InputError(f"cannot open as a ROS bag: {exc}", path=self.path) from None
        except Exception as exc:  # rosbags, sqlite3, yaml and mcap errors alike
            self.close()
            raise InputError(
                f"cannot open as a ROS bag ({type(exc).__name__}: {exc})", path=self.path
            ) from None

    def _add_missing_types(self) -> None:
        """Register known types (Livox, ROS 2 Humble) that the bag did not define."""
        store = self._reader.typestore
        missing = {c.msgtype for c in self._reader.connections} - set(store.fielddefs)
        if missing:
            known = typestore(ros1=not self._reader.is2).fielddefs
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

    def candidates(self, kind: str) -> list[str]:
        """The bag's topics of ``kind`` (a key of :data:`MESSAGE_KINDS`), by name."""
        return [t for t, msgtype in self.topics.items() if msgtype in MESSAGE_KINDS[kind]]

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
        candidates = self.candidates(kind)
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
        messages = self._reader.messages(connections=connections)
        while True:
            try:
                connection, log_time, raw = next(messages)
            except StopIteration:
                return
            except Exception as exc:  # rosbags, sqlite3 and mcap errors alike: a damaged bag
                raise InputError(
                    f"cannot read the messages on {topic} ({type(exc).__name__}: {exc})",
                    path=self.path,
                ) from None
            if connection.topic != topic:  # two connections of one id: a damaged bag index
                raise InputError(
                    f"cannot read the messages on {topic}: a message of {connection.topic} among "
                    "them (damaged bag index)",
                    path=self.path,
                )
            yield int(log_time), connection.msgtype, raw

    def messages(self, topic: str) -> Iterator[tuple[int, object]]:
        """Yield ``(stamp_ns, message)`` of one topic, deserialised by rosbags."""
        for log_time, msgtype, raw in self.raw_messages(topic):
            msg = self._deserialize(raw, msgtype, topic)
            header = getattr(msg, "header", None)
            stamp = header_stamp_ns(header) if header is not None else 0
            yield (stamp or log_time), msg

    def stamps(self, topic: str) -> list[int]:
        """The header stamp of every message of a topic, in time order, nanoseconds.

        Read from the serialised header (no message is decoded); the bag's receive time where
        the stamp is 0, as :meth:`messages`, :meth:`pointclouds` and :meth:`images` yield it.
        Message ``k`` here is message ``k`` of those iterators (their ``only`` argument).
        """
        stamps = []
        for log_time, msgtype, raw in self.raw_messages(topic):
            stamp = raw_header_stamp_ns(bytes(raw[:12]), cdr=self._reader.is2)
            if stamp is None:  # an exotic encoding or a short message: the slow, sure way
                header = getattr(self._deserialize(raw, msgtype, topic), "header", None)
                stamp = header_stamp_ns(header) if header is not None else 0
            stamps.append(stamp or log_time)
        return stamps

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
        only=None,
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
        only : collection of int, optional
            Decode only these messages (0-based, in time order; :meth:`stamps`), skip the rest.

        Yields
        ------
        stamp_ns : int
            Header stamp, nanoseconds.
        cloud : PointCloud
            Points in the LiDAR frame (metres), intensity as stored, times in seconds relative
            to the scan. Points with a non-finite x, y or z are dropped; how many is logged as
            one warning when the iteration ends.
        """
        from nbcalib.io.pointcloud2 import pointcloud2_to_fields

        topic = self.select_topic("point cloud", topic)
        source = f"{self.path} {topic}"
        total = kept = 0  # points read and kept (finite), for one warning at the end
        try:
            for log_time, msgtype, raw in self._chosen_messages(topic, only):
                if msgtype in LIVOX_CUSTOM:
                    stamp, fields = self._livox_fields(raw, msgtype, topic)
                    times = "offset_time" if time_field == "auto" else time_field
                else:
                    msg = self._deserialize(raw, msgtype, topic)
                    stamp = header_stamp_ns(msg.header)
                    fields = pointcloud2_to_fields(msg, source=source)
                    times = time_field
                cloud = pointcloud_from_fields(
                    fields, intensity_channel=intensity_channel, time_field=times, source=source
                )
                total, kept = total + len(fields["x"]), kept + len(cloud)
                yield (stamp or log_time), cloud
        finally:
            warn_dropped_points(source, total - kept, total)

    def _chosen_messages(self, topic: str, only):
        """``raw_messages(topic)``, only those numbered in ``only`` (0-based) when given."""
        if only is None:
            yield from self.raw_messages(topic)
            return
        last = max(only, default=-1)
        for k, message in enumerate(self.raw_messages(topic)):
            if k > last:
                return
            if k in only:
                yield message

    def _livox_fields(self, raw: bytes, msgtype: str, topic: str) -> tuple[int, dict]:
        """Livox CustomMsg -> (stamp_ns, fields), straight from the bytes when possible."""
        parsed = parse_livox_raw(bytes(raw), cdr=self._reader.is2)
        if parsed is not None:
            return parsed
        msg = self._deserialize(raw, msgtype, topic)  # exotic encodings: the slow, sure way
        return livox_fields_from_msg(msg)

    def images(
        self, topic: str | None = None, *, grey: bool = True, only=None
    ) -> Iterator[tuple[int, np.ndarray]]:
        """Yield ``(stamp_ns, image)`` for every message of an Image or CompressedImage topic.

        Parameters
        ----------
        topic : str, optional
            None picks the only image topic.
        grey : bool
            Convert colour to grey with OpenCV's weights (as ``cv_bridge`` to ``mono8``).
        only : collection of int, optional
            Decode only these messages (0-based, in time order; :meth:`stamps`), skip the rest.

        Yields
        ------
        stamp_ns : int
            Header stamp, nanoseconds.
        image : ndarray of shape (H, W) or (H, W, 3), uint8 or uint16
            As stored (8 or 16 bit); colour in RGB order when ``grey=False``.
        """
        topic = self.select_topic("image", topic)
        source = f"{self.path} {topic}"
        for log_time, msgtype, raw in self._chosen_messages(topic, only):
            msg = self._deserialize(raw, msgtype, topic)
            stamp = header_stamp_ns(msg.header) or log_time
            if self.topics[topic] == COMPRESSED_IMAGE:
                yield stamp, decode_compressed_image(msg, grey=grey, source=source)
            else:
                yield stamp, decode_image(msg, grey=grey, source=source)

    def camera_info(self, topic: str | None = None) -> CameraModel:
        """The camera of the first CameraInfo message of a topic (None picks the only one).

        ``fx, fy, cx, cy`` come from ``K``; the model from ``distortion_model`` (``plumb_bob``,
        ``rational_polynomial``, ``equidistant``, and nbcalib's extensions,
        :mod:`nbcalib.io.bag_messages`).
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
                T[:3, 3] = [t.x, t.y, t.z]
                try:
                    if not np.isfinite(T).all():
                        raise ValueError("its translation is not finite")
                    T[:3, :3] = quat_xyzw_to_matrix([q.x, q.y, q.z, q.w])
                except ValueError as exc:  # a zero or non-finite quaternion
                    raise InputError(
                        f"bad transform {tf.header.frame_id} -> {tf.child_frame_id} on {topic}: "
                        f"{exc}",
                        path=self.path,
                    ) from None
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
