"""Writing ROS 1 and ROS 2 bags without a ROS installation (the pure-Python ``rosbags`` package).

:class:`BagWriter` writes point clouds (``sensor_msgs/PointCloud2``, Livox ``CustomMsg``), images
(``sensor_msgs/Image``, ``CompressedImage``), ``sensor_msgs/CameraInfo`` and ``/tf_static``
transforms as ROS 1 (``bag1``), ROS 2 sqlite3 (``bag2``) or ROS 2 mcap (``mcap``), into a
temporary name that is renamed into place on a clean close. ``nbcalib synth`` writes its
synthetic bags with it; :mod:`nbcalib.io.bag` reads them back. The CameraInfo names of nbcalib's
camera models are in :mod:`nbcalib.io.bag_messages`.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io.bag_messages import (
    CAMERA_INFO,
    COMPRESSED_IMAGE,
    IMAGE,
    LIVOX_FIELDS,
    POINTCLOUD2,
    TF_MESSAGE,
    typestore,
)

if TYPE_CHECKING:
    from nbcalib.camera import CameraModel

BAG_FORMATS = ("bag1", "bag2", "mcap")


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
        self._store = typestore(ros1=self._ros1)
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
        rows = zip(*(columns[name].tolist() for name in LIVOX_FIELDS))
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
        """Write a ``sensor_msgs/CameraInfo`` for ``camera``.

        Parameters
        ----------
        camera : CameraModel
            Any nbcalib camera; ``plumb_bob``, ``rational_polynomial`` and ``equidistant`` are
            ROS's names, the others are nbcalib extensions that nbcalib reads back (their names:
            :mod:`nbcalib.io.bag_messages`).
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
