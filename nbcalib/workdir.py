"""The work directory: the one place where a job's products are saved and loaded.

Layout (the nbcalib CLI contract and the reference toolbox, section 1.1), one set of products per
data name ``<name>`` (a bag's file or folder name, or ``000000`` for plain files)::

    WORKDIR/
      calib.json                    camera, meta (bag_names, ...), results; written LAST
      <name>.png                    camera image, 8-bit grey (equalised unless switched off)
      <name>.ply                    dense cloud, binary little-endian float32 x, y, z, intensity
                                    (equalised, in [0, 1)); vertex order = index-map values
      <name>_lidar_intensities.png  LiDAR image, uint8
      <name>_lidar_indices.png      int32 index map (-1 empty) as a 4-channel 8-bit PNG
                                    (:mod:`nbcalib.io.index_map`)
      <name>_matches.json           keypoint matches, the reference's format (find-matches)
      <name>_matches.png            the matches drawn (nbcalib)
      <name>_correspondences.json   the 2D-3D correspondences matching found (nbcalib)
      nbcalib_config.yaml           the config used (nbcalib; ``--config`` reads it back)
      report/, export/              the quality report and exported formats (nbcalib)

nbcalib's additions to ``calib.json`` live under its ``nbcalib`` key, which the reference
ignores: the virtual camera that rendered the LiDAR images (``virtual_camera``), the inputs
(``inputs``), and for each stage what made its product (``made``: the config sections and
inputs it used), from which :class:`nbcalib.pipeline.Calibrator` decides, product by product,
what a resumed job can keep. A directory written by the reference toolbox has none of these:
its products are kept as they are, and read as the reference means them (its virtual camera is
recovered from its LiDAR image, :func:`reference_virtual_camera`).

**Crash safety.** ``calib.json`` marks a finished preprocessing run. :meth:`WorkDir.prepare`
removes an existing one before anything else is written, every product is written to a
temporary file and renamed into place, and :meth:`WorkDir.write_calib` (atomic as well) comes
last. A run that dies half-way therefore leaves a directory without ``calib.json``, which
:meth:`WorkDir.is_complete` and the later commands reject.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.errors import InputError
from nbcalib.io.calib_json import CalibFile, read_calib_json, write_calib_json
from nbcalib.io.index_map import read_index_map, write_index_map
from nbcalib.io.job_record import VirtualCameraEntry
from nbcalib.products import PairData, VirtualCamera

if TYPE_CHECKING:  # the camera module loads the numba kernels
    from nbcalib.camera import CameraModel

__all__ = [
    "CALIB_FILE",
    "CONFIG_FILE",
    "PLAIN_FILES_NAME",
    "WorkDir",
    "check_writable",
    "get_virtual_camera",
    "make_calib",
    "reference_virtual_camera",
    "set_virtual_camera",
]

log = logging.getLogger(__name__)

#: File name of the job description.
CALIB_FILE = "calib.json"
#: File name of the used configuration (:func:`nbcalib.config.write_config`).
CONFIG_FILE = "nbcalib_config.yaml"
#: Data name used for plain point/image files (as the reference's ``preprocess_map``).
PLAIN_FILES_NAME = "000000"
#: Value of the ``meta`` topic fields when the input is not a bag (as ``preprocess_map``).
NOT_APPLICABLE = "N/A"
#: Folders of products derived from a result (nbcalib's report and exports).
DERIVED_FOLDERS = ("report", "export")

_CORRESPONDENCES_FORMAT = "nbcalib-correspondences"


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


def set_virtual_camera(calib: CalibFile, virtual: VirtualCamera) -> None:
    """Record the virtual camera of the LiDAR images under ``nbcalib.virtual_camera``."""
    T = np.asarray(virtual.T_vcam_lidar, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"T_vcam_lidar must be a finite 4 x 4 matrix, got shape {T.shape}")
    fov = None if virtual.fov_deg is None else float(virtual.fov_deg)
    calib.record.virtual_camera = VirtualCameraEntry(virtual.camera.to_dict(), T.tolist(), fov)


def get_virtual_camera(calib: CalibFile) -> VirtualCamera | None:
    """The virtual camera of the work directory's LiDAR images.

    The one recorded by :func:`set_virtual_camera`; in a directory the reference toolbox made
    (no record), the reference's, recovered from the first data name's files
    (:func:`reference_virtual_camera`), read only: nothing is written. None, with a warning
    saying why, when that fails, and None for a ``calib`` that was not read from a file.
    """
    from nbcalib.camera import CameraModel

    entry = calib.record.virtual_camera
    if entry is None:
        if calib.path is None or not calib.bag_names:
            return None
        try:
            virtual = reference_virtual_camera(WorkDir(calib.path.parent), calib.bag_names[0])
        except InputError as exc:
            log.warning(
                "%s records no virtual camera and the reference toolbox's cannot be recovered "
                "(%s): continuing without it",
                calib.path,
                exc,
            )
            return None
        camera = virtual.camera
        log.info(
            "%s records no virtual camera: the reference toolbox's, recovered from %s: %s "
            "%d x %d, intrinsics %s",
            calib.path.name,
            calib.bag_names[0],
            camera.model,
            camera.width,
            camera.height,
            np.round(camera.intrinsics, 3).tolist(),
        )
        return virtual
    try:
        if entry.camera is None or entry.T_vcam_lidar is None:
            raise ValueError("no camera or no T_vcam_lidar")
        camera = CameraModel.from_dict(entry.camera)
        T = np.array(entry.T_vcam_lidar, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("T_vcam_lidar is not a finite 4 x 4 matrix")
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(f"invalid nbcalib.virtual_camera: {exc}", calib.path) from None
    fov = None if entry.lidar_fov_deg is None else float(entry.lidar_fov_deg)
    return VirtualCamera(camera, T, fov)


def reference_virtual_camera(work: WorkDir, name: str) -> VirtualCamera:
    """The virtual camera with which the reference toolbox rendered ``name``'s LiDAR image.

    The reference does not store it, but its choice (reference_toolbox.md section 4) shows in
    the image: a ``2H x H`` image is equirectangular (1920 x 960 there), a ``W x W`` image a
    pinhole looking along LiDAR +x, centred (``cx = cy = W / 2`` under the reference's
    truncating pixel convention, ``(W - 1) / 2`` in nbcalib's), whose ``fx = fy`` (from the
    LiDAR's field of view there) is fitted here to the points the index map shows. Either way
    the camera is :func:`~nbcalib.preprocess.lidar_image.make_virtual_camera`'s, and it must
    put (almost) every point of the index map on its own pixel.

    Parameters
    ----------
    work : WorkDir
        The work directory.
    name : str
        The data name whose ``<name>_lidar_indices.png`` and ``<name>.ply`` are read.

    Returns
    -------
    VirtualCamera
        ``fov_deg`` is the field of view the reference used for a pinhole, else None.

    Raises
    ------
    InputError
        The files cannot be read, or the image is not one the reference renders; names the
        index map.
    """
    from nbcalib.io.ply import read_ply_fields
    from nbcalib.preprocess.lidar_image import (
        PINHOLE_MAX_FOV_DEG,
        R_VCAM_LIDAR_PINHOLE,
        make_virtual_camera,
    )
    from nbcalib.transforms import transform_points

    path = work.lidar_index_path(name)
    index = read_index_map(path)
    height, width = index.shape
    fields = read_ply_fields(work.cloud_path(name))
    if not all(k in fields for k in "xyz"):
        raise InputError("the cloud lacks x, y, z", work.cloud_path(name))
    v, u = np.nonzero(index >= 0)
    if index.max(initial=-1) >= len(fields["x"]):
        raise InputError(
            f"refers to point {index.max()}, {work.cloud_path(name).name} has {len(fields['x'])}",
            path,
        )
    if len(u) < 10:
        raise InputError(f"shows only {len(u)} points", path)
    points = np.column_stack([fields[k][index[v, u]] for k in "xyz"]).astype(np.float64)
    uv = np.column_stack([u, v]).astype(np.float64)
    fov = None
    if width == 2 * height:
        camera, T_vcam_lidar = make_virtual_camera(math.pi, equirectangular_size=(width, height))
    elif width == height:
        p = points @ R_VCAM_LIDAR_PINHOLE.T
        ahead = p[:, 2] > 0
        ab = p[ahead, :2] / p[ahead, 2:]
        # fx = fy by least squares on u - c = fx a, v - c = fx b
        spread = float(np.sum(ab * ab))
        fx = float(np.sum(ab * (uv[ahead] - (width - 1) / 2.0))) / spread if spread else 0.0
        fov = 2.0 * math.atan(width / (2.0 * fx)) if fx > 0.0 else math.pi
        if math.degrees(fov) >= PINHOLE_MAX_FOV_DEG:
            raise InputError("a square LiDAR image, but no pinhole looking along +x shows it", path)
        camera, T_vcam_lidar = make_virtual_camera(fov, pinhole_size=width)
    else:
        raise InputError(
            f"a {width} x {height} LiDAR image: the reference toolbox renders 1024 x 1024 "
            "(pinhole) or 1920 x 960 (equirectangular)",
            path,
        )
    projected, valid = camera.project(transform_points(T_vcam_lidar, points))
    on_pixel = valid & np.all(np.floor(projected + 0.5) == uv, axis=1)
    if np.mean(on_pixel) < 0.99:
        raise InputError(
            f"only {np.mean(on_pixel):.0%} of its points lie on their pixels through the "
            f"reference toolbox's {camera.model} virtual camera",
            path,
        )
    return VirtualCamera(camera, T_vcam_lidar, None if fov is None else math.degrees(fov))


def check_writable(path: str | os.PathLike) -> None:
    """Refuse, before any work is done, a folder that cannot be written or made.

    ``path`` need not exist: its nearest existing ancestor must be a folder in which a file can
    be created (a probe file is made and removed, which also catches read-only mounts).

    Raises
    ------
    InputError
        Naming the folder (or the file in the way) and the reason.
    """
    target = Path(path)
    while not target.exists() and target.parent != target:
        target = target.parent
    if not target.is_dir():
        raise InputError("is a file, not a folder: cannot write into it", target)
    try:
        with tempfile.TemporaryFile(dir=target):
            pass
    except OSError as exc:
        reason = (exc.strerror or type(exc).__name__).lower()
        raise InputError(f"cannot write here ({reason})", target) from None


# --------------------------------------------------------------------------------------------
# The directory


class WorkDir:
    """A work directory (module docstring): paths, and saving and loading each product.

    Parameters
    ----------
    path : str or os.PathLike
        The directory (need not exist until :meth:`prepare`).
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

    @property
    def config_path(self) -> Path:
        """``nbcalib_config.yaml``: the config used."""
        return self.path / CONFIG_FILE

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
        """``<name>_matches.json``: keypoint matches (find-matches, or the reference's script)."""
        return self.path / f"{name}_matches.json"

    def matches_picture_path(self, name: str) -> Path:
        """``<name>_matches.png``: the matches drawn."""
        return self.path / f"{name}_matches.png"

    def correspondences_path(self, name: str) -> Path:
        """``<name>_correspondences.json``: the 2D-3D correspondences of matching."""
        return self.path / f"{name}_correspondences.json"

    def product_paths(self, name: str) -> list[Path]:
        """The four files preprocessing writes for ``name``."""
        return [
            self.image_path(name),
            self.cloud_path(name),
            self.lidar_intensity_path(name),
            self.lidar_index_path(name),
        ]

    def match_paths(self, name: str) -> list[Path]:
        """The files matching writes for ``name``."""
        return [
            self.matches_path(name),
            self.matches_picture_path(name),
            self.correspondences_path(name),
        ]

    # ---------------------------------------------------------------- calib.json
    def read_calib(self) -> CalibFile:
        """Read ``calib.json`` (:class:`InputError` if missing or invalid)."""
        if not self.path.is_dir():
            raise InputError("work directory not found", self.path)
        return read_calib_json(self.calib_path)

    def write_calib(self, calib: CalibFile) -> None:
        """Write ``calib.json`` (atomically): the last step, which marks the directory complete.

        Every name in ``calib.meta["bag_names"]`` must have its products on disk.
        """
        for name in calib.bag_names:
            missing = [p.name for p in self.product_paths(name) if not p.is_file()]
            if missing:
                raise ValueError(f"cannot finish {self.path}: missing {', '.join(missing)}")
        write_calib_json(self.calib_path, calib)

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

    def require_preprocessed(self) -> CalibFile:
        """``calib.json`` of a preprocessed directory, else an :class:`InputError` saying why."""
        if not self.path.is_dir():
            raise InputError("work directory not found", self.path)
        if not self.calib_path.is_file():
            raise InputError("no calib.json: run 'nbcalib preprocess' first", self.calib_path)
        calib = self.read_calib()
        if not calib.bag_names:
            raise InputError("meta.bag_names is empty: nothing to use", self.calib_path)
        return calib

    def check_writable(self) -> None:
        """:func:`check_writable` for this directory (it need not exist yet)."""
        check_writable(self.path)

    # ---------------------------------------------------------------- preprocessing
    def prepare(self) -> None:
        """Create the directory and remove what a new preprocessing run makes stale.

        ``calib.json`` goes first: without it the directory does not look complete until
        :meth:`write_calib` has run, whatever happens in between. The report and exports of an
        earlier result go as well (:meth:`remove_derived`).
        """
        if self.path.exists() and not self.path.is_dir():
            raise InputError("exists and is not a directory", self.path)
        try:
            self.path.mkdir(parents=True, exist_ok=True)
            self.calib_path.unlink(missing_ok=True)
        except OSError as exc:
            raise InputError(f"cannot write here: {exc.strerror or exc}", self.path) from None
        self.remove_derived()

    def write_pair(self, pair: PairData) -> None:
        """Write one pair's products (each atomically); ``calib.json`` is not touched.

        Matching products of an older LiDAR image (``<name>_matches.json`` ...) are removed.
        """
        from nbcalib.io.image import write_png
        from nbcalib.io.ply import write_ply

        _check_name(pair.name)
        image = np.asarray(pair.image)
        if image.ndim != 2 or image.dtype != np.uint8:
            raise ValueError(f"image must be (H, W) uint8, got {image.dtype} {image.shape}")
        points = np.asarray(pair.points_lidar, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points_lidar must have shape (N, 3), got {points.shape}")
        values = np.asarray(pair.intensities, dtype=np.float64)
        if values.shape != (len(points),):
            raise ValueError(f"intensities must have shape ({len(points)},), got {values.shape}")
        lidar_image = pair.lidar_image
        index = np.asarray(lidar_image.index)
        if index.size and index.max() >= len(points):
            raise ValueError(
                f"the index map refers to point {index.max()}, the cloud has {len(points)}"
            )
        if lidar_image.intensity.shape != index.shape:
            raise ValueError("lidar_image intensity and index maps differ in size")
        if not self.path.is_dir():
            raise ValueError(f"{self.path} does not exist; call prepare() first")
        for path in self.match_paths(pair.name):
            path.unlink(missing_ok=True)
        write_png(self.image_path(pair.name), image)
        write_ply(self.cloud_path(pair.name), points.astype(np.float32), values.astype(np.float32))
        write_png(self.lidar_intensity_path(pair.name), np.asarray(lidar_image.intensity, np.uint8))
        write_index_map(self.lidar_index_path(pair.name), index)

    def load_pair(self, name: str, *, budget=None) -> PairData:
        """Load one data name's products and check that they fit together.

        The cloud is read when its points are first asked for (:class:`~nbcalib.clouds.Cloud`,
        its size and fields checked from the PLY's header now), and kept in ``budget``
        (a :class:`~nbcalib.clouds.MemoryBudget`; default: kept once read, without limit).

        Raises
        ------
        InputError
            A missing or corrupt file, a cloud without intensity, or an index map that refers to
            points the cloud does not have; the message names the file.
        """
        from nbcalib.clouds import Cloud, MemoryBudget
        from nbcalib.io.image import read_image
        from nbcalib.io.ply import read_ply_vertex_header

        _check_name(name)
        image = _read_uint8(self.image_path(name), read_image)
        cloud_path = self.cloud_path(name)
        size, names = read_ply_vertex_header(cloud_path)
        missing = [k for k in ("x", "y", "z", "intensity") if k not in names]
        if missing:
            raise InputError(f"the cloud lacks the vertex properties {missing}", cloud_path)
        lidar_intensity = _read_uint8(self.lidar_intensity_path(name), read_image)
        index_path = self.lidar_index_path(name)
        index = read_index_map(index_path)
        if index.shape != lidar_intensity.shape:
            raise InputError(
                f"index map is {index.shape[1]}x{index.shape[0]}, the LiDAR image "
                f"{lidar_intensity.shape[1]}x{lidar_intensity.shape[0]}",
                index_path,
            )
        if index.size and index.max() >= size:
            raise InputError(
                f"index map refers to point {index.max()}, {cloud_path.name} has {size}",
                index_path,
            )
        del lidar_intensity, index  # checked: read again when asked for
        lidar_image = StoredLidarImage(self, name)
        budget = MemoryBudget(None) if budget is None else budget
        cloud = Cloud(path=cloud_path, size=size, budget=budget)
        return PairData(name, image, lidar_image=lidar_image, cloud=cloud)

    def load_pairs(self, names=None, *, budget=None) -> list[PairData]:
        """:meth:`load_pair` for each name (default: every name of ``calib.json``)."""
        names = self.names() if names is None else names
        return [self.load_pair(name, budget=budget) for name in names]

    # ---------------------------------------------------------------- matching
    def write_matches(self, found, pair: PairData, *, draw: bool = True) -> None:
        """Save one pair's matching result (:class:`~nbcalib.matching.find.PairMatches`).

        Writes ``<name>_correspondences.json`` (nbcalib's product: every correspondence, its
        camera pixel, cloud row and confidence), ``<name>_matches.json`` (the reference's
        format: the correspondences the stored LiDAR image shows) and, with ``draw``,
        ``<name>_matches.png`` (:func:`~nbcalib.matching.draw.draw_pair_matches`: drawn on
        the LiDAR image that was matched).
        """
        from nbcalib.io._files import write_text_atomic
        from nbcalib.io.image import write_png
        from nbcalib.matching.draw import draw_pair_matches
        from nbcalib.matching.matches import write_matches_json

        corr = found.correspondences
        doc = {
            "format": _CORRESPONDENCES_FORMAT,
            "version": 1,
            "name": pair.name,
            "matcher": found.matcher,
            "n_matches": int(corr.n_matches),
            "uv_camera": corr.uv_camera.tolist(),
            "point_index": corr.point_index.tolist(),
            "confidence": None if corr.confidence is None else corr.confidence.tolist(),
        }
        write_text_atomic(self.correspondences_path(pair.name), json.dumps(doc) + "\n")
        write_matches_json(self.matches_path(pair.name), found.matches)
        picture = self.matches_picture_path(pair.name)
        if draw:
            write_png(picture, draw_pair_matches(pair.image, found, pair.lidar_image.intensity))
        else:
            picture.unlink(missing_ok=True)

    def has_matches(self, name: str) -> bool:
        """Matching's product for ``name`` is here (nbcalib's or the reference's)."""
        return self.correspondences_path(name).is_file() or self.matches_path(name).is_file()

    def read_correspondences(self, pair: PairData, *, search_radius: float):
        """One pair's 2D-3D correspondences, as matching saved them.

        nbcalib's ``<name>_correspondences.json`` when present; else the reference's
        ``<name>_matches.json``, lifted through the index map (LiDAR keypoints on an empty
        pixel take the nearest point within ``search_radius`` pixels).

        Raises
        ------
        InputError
            Neither file, or a corrupt one; the message says to run find-matches.
        """
        from nbcalib.matching.correspondences import Correspondences, correspondences_from_matches
        from nbcalib.matching.matches import read_matches_json

        path = self.correspondences_path(pair.name)
        if not path.is_file():
            matches_path = self.matches_path(pair.name)
            if not matches_path.is_file():
                raise InputError("no matches: run 'nbcalib find-matches' first", matches_path)
            matches = read_matches_json(matches_path)
            return correspondences_from_matches(
                matches,
                pair.lidar_index,
                pair.points_lidar,
                search_radius=search_radius,
                name=pair.name,
            )
        try:
            doc = json.loads(path.read_text())
            if doc.get("format") != _CORRESPONDENCES_FORMAT:
                raise ValueError(f"format is not {_CORRESPONDENCES_FORMAT}")
            uv = np.array(doc["uv_camera"], dtype=np.float64).reshape(-1, 2)
            rows = np.array(doc["point_index"], dtype=np.int64).reshape(-1)
            confidence = doc["confidence"]
            if confidence is not None:
                confidence = np.array(confidence, dtype=np.float64).reshape(-1)
            if len(uv) != len(rows) or (confidence is not None and len(confidence) != len(rows)):
                raise ValueError("uv_camera, point_index and confidence differ in length")
            if rows.size and (rows.min() < 0 or rows.max() >= len(pair.points_lidar)):
                raise ValueError(f"point_index outside the cloud's {len(pair.points_lidar)} rows")
            n_matches = int(doc["n_matches"])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise InputError(
                f"corrupt correspondences ({exc}); run find-matches again", path
            ) from None
        return Correspondences(
            uv_camera=uv,
            points_lidar=pair.points_lidar[rows],
            uv_lidar=np.full((len(rows), 2), np.nan),  # pixels of views that are not stored
            point_index=rows,
            pair=np.zeros(len(rows), dtype=np.int64),
            names=(pair.name,),
            n_matches=n_matches,
            confidence=confidence,
        )

    # ---------------------------------------------------------------- derived products
    def remove_derived(self) -> None:
        """Remove the report and exports: they describe a result that is about to change."""
        for folder in DERIVED_FOLDERS:
            target = self.path / folder
            if target.is_dir():
                shutil.rmtree(target, ignore_errors=True)


def _check_name(name: str) -> None:
    if not isinstance(name, str) or not name or name != Path(name).name or name.startswith("."):
        raise ValueError(f"a data name must be a plain file name, got {name!r}")


class StoredLidarImage:
    """A pair's LiDAR image and index map in a work directory, read each time asked for.

    What :class:`~nbcalib.preprocess.lidar_image.LidarImage` holds, without its depth: a
    job's pairs keep 5 MB less each (a 1024 x 1024 virtual camera) between the few stages that
    look at them (matching, the manual picker, the report's figures).
    """

    depth = None

    def __init__(self, work: WorkDir, name: str):
        self.work, self.name = work, name

    def __repr__(self) -> str:
        return f"StoredLidarImage({self.name!r})"

    @property
    def intensity(self) -> np.ndarray:
        """``round(255 * intensity)`` of the nearest point (H, W), uint8."""
        from nbcalib.io.image import read_image

        return _read_uint8(self.work.lidar_intensity_path(self.name), read_image)

    @property
    def index(self) -> np.ndarray:
        """Row of the nearest point in the cloud (H, W), int32, -1 where empty."""
        return read_index_map(self.work.lidar_index_path(self.name))

    @property
    def filled(self) -> np.ndarray:
        """Boolean (H, W) mask of pixels that show a point."""
        return self.index >= 0


def _read_uint8(path: Path, read_image) -> np.ndarray:
    image = read_image(path, grey=True)
    if image.dtype != np.uint8:
        raise InputError(f"expected an 8-bit image, got {image.dtype}", path)
    return image
