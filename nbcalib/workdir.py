"""The work directory: one calibration job's files, shared with the reference toolbox.

Layout (the nbcalib CLI contract and the reference toolbox, section 1.1), one set of products per
data name ``<name>`` (a bag's file or folder name, or ``000000`` for plain files)::

    WORKDIR/
      calib.json                    camera, meta (bag_names, ...), results; written LAST
      <name>.png                    camera image, 8-bit grey (equalised unless switched off)
      <name>.ply                    dense cloud, binary little-endian float32 x, y, z, intensity
                                    (equalised, in [0, 1)); vertex order = index-map values
      <name>_lidar_intensities.png  LiDAR image, uint8
      <name>_lidar_indices.png      int32 index map (-1 empty) as a 4-channel 8-bit PNG: the raw
                                    little-endian bytes of each int32 as B, G, R, A
      <name>_matches.json           keypoint matches (written by find-matches)

The index map decodes with ``cv2.imread(path, cv2.IMREAD_UNCHANGED).view('<i4')[..., 0]``
(:func:`decode_index_map`); an empty pixel is -1, all four bytes 0xFF.

**Crash safety.** ``calib.json`` marks a finished preprocessing run. :meth:`WorkDir.prepare`
removes an existing one before anything else is written, every product is written to a
temporary file and renamed into place, and :meth:`WorkDir.write_calib` (atomic as well) comes
last. A run that dies half-way therefore leaves a directory without ``calib.json``, which
:meth:`WorkDir.is_complete` and the later commands reject.

nbcalib also records the virtual camera that rendered the LiDAR images under
``calib.json``'s ``nbcalib.virtual_camera`` (:func:`set_virtual_camera`); the reference ignores
it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.io.calib_json import CalibFile, read_calib_json, write_calib_json

__all__ = [
    "CALIB_FILE",
    "PLAIN_FILES_NAME",
    "WorkDir",
    "WorkPair",
    "decode_index_map",
    "encode_index_map",
    "get_virtual_camera",
    "make_calib",
    "read_index_map",
    "set_virtual_camera",
    "write_index_map",
]

#: File name of the job description.
CALIB_FILE = "calib.json"
#: Data name used for plain point/image files (as the reference's ``preprocess_map``).
PLAIN_FILES_NAME = "000000"
#: Value of the ``meta`` topic fields when the input is not a bag (as ``preprocess_map``).
NOT_APPLICABLE = "N/A"

_INDEX_DTYPE = np.dtype("<i4")
_VIRTUAL_CAMERA_KEY = "virtual_camera"


# --------------------------------------------------------------------------------------------
# Index map <-> 4-channel PNG


def encode_index_map(index) -> np.ndarray:
    """Bytes of an int32 index map as an (H, W, 4) uint8 image (OpenCV's B, G, R, A order).

    Parameters
    ----------
    index : array_like of shape (H, W), integer
        Point indices, -1 where empty; every value must fit int32.

    Returns
    -------
    ndarray of shape (H, W, 4), uint8
        Channel ``k`` holds byte ``k`` of the little-endian int32; pass it to ``cv2.imwrite`` /
        ``cv2.imencode`` as is (OpenCV treats 4 channels as BGRA).
    """
    index = np.asarray(index)
    if index.ndim != 2 or index.dtype.kind not in "iu":
        raise ValueError(f"index must be an (H, W) integer array, got {index.dtype} {index.shape}")
    info = np.iinfo(np.int32)
    if index.size and (index.min() < -1 or index.max() > info.max):
        raise ValueError("index values must be -1 or in [0, 2**31 - 1]")
    little = np.ascontiguousarray(index, dtype=_INDEX_DTYPE)
    return little.view(np.uint8).reshape(*index.shape, 4)


def decode_index_map(image) -> np.ndarray:
    """Inverse of :func:`encode_index_map`: (H, W, 4) uint8 (B, G, R, A) to (H, W) int32."""
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 4 or image.dtype != np.uint8:
        raise ValueError(f"expected an (H, W, 4) uint8 image, got {image.dtype} {image.shape}")
    values = np.ascontiguousarray(image).view(_INDEX_DTYPE)[..., 0]
    return values.astype(np.int32)


def write_index_map(path, index) -> None:
    """Write an index map as the reference's 4-channel 8-bit PNG, atomically."""
    import cv2

    from nbcalib.io._files import write_bytes_atomic

    ok, encoded = cv2.imencode(".png", encode_index_map(index))
    if not ok:  # pragma: no cover - OpenCV encodes every (H, W, 4) uint8 image
        raise RuntimeError("OpenCV could not encode the index map as PNG")
    write_bytes_atomic(path, [encoded.tobytes()])


def read_index_map(path) -> np.ndarray:
    """Read ``<name>_lidar_indices.png``.

    Returns
    -------
    ndarray of shape (H, W), int32
        Point indices, -1 where empty.

    Raises
    ------
    InputError
        Missing or undecodable file, not a 4-channel 8-bit image, or values below -1.
    """
    import cv2

    path = Path(path)
    image = cv2.imdecode(_read_file_bytes(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError("cannot decode as an image (corrupt or unknown format)", path)
    if image.ndim != 3 or image.shape[2] != 4 or image.dtype != np.uint8:
        channels = 1 if image.ndim == 2 else image.shape[2]
        raise InputError(
            f"not an index map: expected a 4-channel 8-bit PNG, got {channels} channel(s) of "
            f"{image.dtype}",
            path,
        )
    index = decode_index_map(image)
    if index.size and index.min() < -1:
        raise InputError(f"not an index map: holds the value {index.min()} (< -1)", path)
    return index


def _read_file_bytes(path: Path) -> np.ndarray:
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except FileNotFoundError:
        raise InputError("file not found", path) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a file", path) from None
    if data.size == 0:
        raise InputError("empty file", path)
    return data


# --------------------------------------------------------------------------------------------
# calib.json helpers


def make_calib(
    camera: CameraModel,
    bag_names: list[str],
    *,
    data_path: str = "",
    camera_info_topic: str = NOT_APPLICABLE,
    image_topic: str = NOT_APPLICABLE,
    points_topic: str = NOT_APPLICABLE,
    intensity_channel: str = "auto",
) -> CalibFile:
    """A fresh :class:`~nbcalib.io.calib_json.CalibFile` as the reference's ``preprocess``.

    ``meta`` gets ``data_path``, the three topics (``"N/A"`` for plain files, as the reference's
    ``preprocess_map``), ``intensity_channel`` and ``bag_names``; ``camera`` the real camera.
    """
    if not bag_names or not all(isinstance(n, str) and n for n in bag_names):
        raise ValueError(f"bag_names must be non-empty strings, got {bag_names!r}")
    calib = CalibFile()
    calib.set_camera(camera)
    calib.meta = {
        "data_path": str(data_path),
        "camera_info_topic": camera_info_topic,
        "image_topic": image_topic,
        "points_topic": points_topic,
        "intensity_channel": intensity_channel,
        "bag_names": list(bag_names),
    }
    return calib


def set_virtual_camera(calib: CalibFile, camera: CameraModel, T_vcam_lidar) -> None:
    """Record the virtual camera of the LiDAR images under ``nbcalib.virtual_camera``.

    Parameters
    ----------
    calib : CalibFile
        Updated in place.
    camera : CameraModel
        The virtual camera (:func:`nbcalib.preprocess.lidar_image.make_virtual_camera`).
    T_vcam_lidar : array_like of shape (4, 4)
        ``p_vcam = T_vcam_lidar @ p_lidar``.
    """
    T = np.asarray(T_vcam_lidar, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"T_vcam_lidar must be a finite 4 x 4 matrix, got shape {T.shape}")
    calib.nbcalib[_VIRTUAL_CAMERA_KEY] = {
        "camera": camera.to_dict(),
        "T_vcam_lidar": T.tolist(),
    }


def get_virtual_camera(calib: CalibFile) -> tuple[CameraModel, np.ndarray] | None:
    """The virtual camera recorded by :func:`set_virtual_camera`, or None (reference-made dirs).

    Returns
    -------
    camera : CameraModel
    T_vcam_lidar : ndarray of shape (4, 4), float64
    """
    entry = calib.nbcalib.get(_VIRTUAL_CAMERA_KEY)
    if entry is None:
        return None
    try:
        camera = CameraModel.from_dict(entry["camera"])
        T = np.array(entry["T_vcam_lidar"], dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("T_vcam_lidar is not a finite 4 x 4 matrix")
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"invalid nbcalib.{_VIRTUAL_CAMERA_KEY}: {exc}", calib.path) from None
    return camera, T


# --------------------------------------------------------------------------------------------
# The directory


@dataclass(frozen=True)
class WorkPair:
    """One data name's products, as loaded from a work directory.

    Attributes
    ----------
    name : str
        The data name (``<name>.png`` etc.).
    image : ndarray of shape (H, W), uint8
        The camera image (equalised grey).
    points_lidar : ndarray of shape (N, 3), float64
        The dense cloud in the LiDAR frame, metres (stored as float32).
    intensities : ndarray of shape (N,), float64
        Equalised intensities in [0, 1) (stored as float32).
    lidar_intensity : ndarray of shape (H', W'), uint8
        The LiDAR image.
    lidar_index : ndarray of shape (H', W'), int32
        Row of ``points_lidar`` shown by each LiDAR-image pixel, -1 where empty.
    """

    name: str
    image: np.ndarray
    points_lidar: np.ndarray
    intensities: np.ndarray
    lidar_intensity: np.ndarray
    lidar_index: np.ndarray


class WorkDir:
    """A work directory (module docstring): paths, writing one pair's products, loading them.

    Parameters
    ----------
    path : str or os.PathLike
        The directory (need not exist until :meth:`prepare`).

    Examples
    --------
    >>> wd = WorkDir("out")                                      # doctest: +SKIP
    >>> wd.prepare()                                             # doctest: +SKIP
    >>> wd.write_pair("000000", image=img, points_lidar=pts, intensities=eq,
    ...               lidar_image=render_lidar_image(vcam, T_vcam_lidar, pts, eq))  # doctest: +SKIP
    >>> wd.write_calib(make_calib(camera, ["000000"]))          # doctest: +SKIP
    """

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)

    def __repr__(self) -> str:
        return f"WorkDir({str(self.path)!r})"

    # ---------------------------------------------------------------- paths
    @property
    def calib_path(self) -> Path:
        """``calib.json``."""
        return self.path / CALIB_FILE

    def image_path(self, name: str) -> Path:
        """``<name>.png``: the camera image."""
        return self.path / f"{name}.png"

    def cloud_path(self, name: str) -> Path:
        """``<name>.ply``: the dense cloud."""
        return self.path / f"{name}.ply"

    def lidar_intensity_path(self, name: str) -> Path:
        """``<name>_lidar_intensities.png``: the LiDAR image."""
        return self.path / f"{name}_lidar_intensities.png"

    def lidar_index_path(self, name: str) -> Path:
        """``<name>_lidar_indices.png``: the index map."""
        return self.path / f"{name}_lidar_indices.png"

    def matches_path(self, name: str) -> Path:
        """``<name>_matches.json``: keypoint matches (find-matches)."""
        return self.path / f"{name}_matches.json"

    def product_paths(self, name: str) -> list[Path]:
        """The four files preprocessing writes for ``name``."""
        return [
            self.image_path(name),
            self.cloud_path(name),
            self.lidar_intensity_path(name),
            self.lidar_index_path(name),
        ]

    # ---------------------------------------------------------------- writing
    def prepare(self) -> None:
        """Create the directory and remove an existing ``calib.json`` before products change.

        Without ``calib.json`` the directory does not look complete until :meth:`write_calib`
        has run, whatever happens in between.
        """
        if self.path.exists() and not self.path.is_dir():
            raise InputError("exists and is not a directory", self.path)
        self.path.mkdir(parents=True, exist_ok=True)
        self.calib_path.unlink(missing_ok=True)

    def write_pair(
        self,
        name: str,
        *,
        image,
        points_lidar,
        intensities,
        lidar_image,
    ) -> None:
        """Write one data name's products (each atomically); ``calib.json`` is not touched.

        A stale ``<name>_matches.json`` (keypoints of an older LiDAR image) is removed.

        Parameters
        ----------
        name : str
            Data name: a bag's name, or :data:`PLAIN_FILES_NAME`.
        image : ndarray of shape (H, W), uint8
            The camera image to store (already equalised if wanted).
        points_lidar : array_like of shape (N, 3)
            The dense cloud, LiDAR frame, metres; written as float32 in this order.
        intensities : array_like of shape (N,)
            Equalised intensities in [0, 1], written as float32.
        lidar_image : LidarImage
            Rendered from exactly these points (its indices refer to their rows).
        """
        from nbcalib.io.image import write_png
        from nbcalib.io.ply import write_ply

        _check_name(name)
        image = np.asarray(image)
        if image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(f"image must be (H, W) uint8, got {image.dtype} {image.shape}")
        points = np.asarray(points_lidar, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points_lidar must have shape (N, 3), got {points.shape}")
        values = np.asarray(intensities, dtype=np.float64)
        if values.shape != (len(points),):
            raise ValueError(f"intensities must have shape ({len(points)},), got {values.shape}")
        index = np.asarray(lidar_image.index)
        if index.size and index.max() >= len(points):
            raise ValueError(
                f"the index map refers to point {index.max()}, the cloud has {len(points)}"
            )
        if lidar_image.intensity.shape != index.shape:
            raise ValueError("lidar_image intensity and index maps differ in size")
        if not self.path.is_dir():
            raise ValueError(f"{self.path} does not exist; call prepare() first")
        self.matches_path(name).unlink(missing_ok=True)
        write_png(self.image_path(name), image)
        write_ply(self.cloud_path(name), points.astype(np.float32), values.astype(np.float32))
        write_png(self.lidar_intensity_path(name), np.asarray(lidar_image.intensity, np.uint8))
        write_index_map(self.lidar_index_path(name), index)

    def write_calib(self, calib: CalibFile) -> None:
        """Write ``calib.json`` (atomically): the last step, which marks the directory complete.

        Every name in ``calib.meta["bag_names"]`` must have its products on disk.
        """
        for name in calib.bag_names:
            missing = [p.name for p in self.product_paths(name) if not p.is_file()]
            if missing:
                raise ValueError(f"cannot finish {self.path}: missing {', '.join(missing)}")
        write_calib_json(self.calib_path, calib)

    # ---------------------------------------------------------------- reading
    def read_calib(self) -> CalibFile:
        """Read ``calib.json`` (:class:`InputError` if missing or invalid)."""
        if not self.path.is_dir():
            raise InputError("work directory not found", self.path)
        return read_calib_json(self.calib_path)

    def names(self) -> list[str]:
        """Data names: ``meta.bag_names`` of ``calib.json``, else the stems of ``*.ply`` files."""
        if self.calib_path.is_file():
            names = self.read_calib().bag_names
            if names:
                return list(names)
        return sorted(p.stem for p in self.path.glob("*.ply") if not p.name.startswith("."))

    def is_complete(self) -> bool:
        """``calib.json`` is readable and every one of its names has its four products."""
        try:
            names = self.read_calib().bag_names
        except InputError:
            return False
        return bool(names) and all(p.is_file() for n in names for p in self.product_paths(n))

    def load_pair(self, name: str) -> WorkPair:
        """Load one data name's products and check that they fit together.

        Raises
        ------
        InputError
            A missing or corrupt file, a cloud without intensity, or an index map that refers to
            points the cloud does not have; the message names the file.
        """
        from nbcalib.io.image import read_image
        from nbcalib.io.ply import read_ply_fields

        _check_name(name)
        image = _read_uint8(self.image_path(name), read_image)
        cloud_path = self.cloud_path(name)
        fields = read_ply_fields(cloud_path)
        missing = [k for k in ("x", "y", "z", "intensity") if k not in fields]
        if missing:
            raise InputError(f"the cloud lacks the vertex properties {missing}", cloud_path)
        points = np.column_stack([fields[k] for k in "xyz"]).astype(np.float64)
        intensities = np.asarray(fields["intensity"], dtype=np.float64)
        lidar_intensity = _read_uint8(self.lidar_intensity_path(name), read_image)
        index_path = self.lidar_index_path(name)
        index = read_index_map(index_path)
        if index.shape != lidar_intensity.shape:
            raise InputError(
                f"index map is {index.shape[1]}x{index.shape[0]}, the LiDAR image "
                f"{lidar_intensity.shape[1]}x{lidar_intensity.shape[0]}",
                index_path,
            )
        if index.size and index.max() >= len(points):
            raise InputError(
                f"index map refers to point {index.max()}, {cloud_path.name} has {len(points)}",
                index_path,
            )
        return WorkPair(name, image, points, intensities, lidar_intensity, index)


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not name or name != Path(name).name or name.startswith("."):
        raise ValueError(f"a data name must be a plain file name, got {name!r}")


def _read_uint8(path: Path, read_image) -> np.ndarray:
    image = read_image(path, grey=True)
    if image.dtype != np.uint8:
        raise InputError(f"expected an 8-bit image, got {image.dtype}", path)
    return image
