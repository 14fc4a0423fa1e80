"""Calibrate from arrays or files in a few lines: :func:`calibrate`.

>>> import nbcalib
>>> result = nbcalib.calibrate(points, intensities, image, "camera.yaml")   # doctest: +SKIP
>>> result.T_lidar_camera            # p_lidar = T_lidar_camera @ p_camera  # doctest: +SKIP
>>> result.pairs[0].lidar_image      # the intermediate products            # doctest: +SKIP

Several cameras around one LiDAR: images and cameras by camera name (and, when the
camera-to-camera extrinsics are known, the rig):

>>> rig = nbcalib.calibrate(points, None, {"front": img0, "left": img1},           # doctest: +SKIP
...                         {"front": "front.yaml", "left": "left.yaml"})
>>> rig.cameras["left"].T_lidar_camera, rig.T_ref_camera["left"]                   # doctest: +SKIP

A thin shell over :class:`nbcalib.pipeline.Calibrator`, the pipeline ``nbcalib run`` runs: the
same stages in the same order, in memory (or in ``workdir`` when given, which the command line
can then continue).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from nbcalib.errors import InputError
from nbcalib.products import CalibrationResult
from nbcalib.progress import api_output
from nbcalib.warmup import compiling_note

__all__ = ["ArrayInputs", "CalibrationResult", "calibrate"]


@dataclass
class ArrayInputs:
    """Inputs given as arrays or file names (one pair each), for the pipeline.

    Attributes
    ----------
    clouds : list
        Per pair: an (N, 3) or (N, 4) array, or a point cloud file.
    intensities : list
        Per pair: an (N,) array or None.
    images : list
        Per pair: an image array or file.
    camera : CameraModel or str
        The camera, or its file.
    """

    clouds: list
    intensities: list
    images: list
    camera: object

    empty = False

    def to_dict(self) -> None:
        """Arrays are not recorded as a job's inputs."""
        return None

    def gather(self, config):
        """(pairs, camera, data_path) as :meth:`nbcalib.preprocess.inputs.InputSpec.gather`."""
        from nbcalib.preprocess.sources import PairInput

        grey = [_load_image(image) for image in self.images]
        camera = _load_camera(self.camera, grey[0].shape)
        pairs = [
            PairInput(
                f"{k:06d}",
                [_load_cloud(cloud, values, config.intensity_channel)],
                image,
                f"image {k}",
            )
            for k, (cloud, values, image) in enumerate(zip(self.clouds, self.intensities, grey))
        ]
        return pairs, camera, ""


def _as_list(value, what: str) -> list:
    """One pair's input, or a list/tuple of them (one per pair)."""
    if isinstance(value, (list, tuple)):
        if not value:
            raise ValueError(f"{what}: empty list")
        return list(value)
    return [value]


def _clouds(points, intensities) -> tuple[list, list]:
    """The clouds (one per pair) and their intensities (None for each when not given)."""
    clouds = _as_list(points, "points")
    values = _as_list(intensities, "intensities") if intensities is not None else [None]
    if len(values) == 1 and len(clouds) > 1 and values[0] is None:
        values = values * len(clouds)
    return clouds, values


def _load_cloud(points, intensities, channel: str):
    """A :class:`~nbcalib.io.pointcloud.PointCloud` from a file or from arrays."""
    from nbcalib.io.pointcloud import PointCloud, read_pointcloud

    if isinstance(points, (str, os.PathLike)):
        cloud = read_pointcloud(points, intensity_channel=channel)
        if intensities is not None:
            cloud = PointCloud(cloud.points, _intensities(intensities, len(cloud)), cloud.times)
        return cloud
    xyz = np.ascontiguousarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] not in (3, 4):
        raise ValueError(f"points must have shape (N, 3) or (N, 4), got {xyz.shape}")
    if intensities is None:
        if xyz.shape[1] != 4:
            raise ValueError("give intensities, or points of shape (N, 4) with intensity last")
        intensities = xyz[:, 3]
    values = _intensities(intensities, len(xyz))
    keep = np.all(np.isfinite(xyz[:, :3]), axis=1) & np.isfinite(values)
    return PointCloud(np.ascontiguousarray(xyz[keep, :3]), values[keep])


def _intensities(values, n: int) -> np.ndarray:
    values = np.ascontiguousarray(values, dtype=np.float64).reshape(-1)
    if values.shape != (n,):
        raise ValueError(f"intensities must have shape ({n},), got {values.shape}")
    return values


def _load_image(image) -> np.ndarray:
    from nbcalib.io.image import read_image

    if isinstance(image, (str, os.PathLike)):
        if not Path(image).is_file():
            raise InputError("image not found", image)
        return read_image(image, grey=True)
    array = np.asarray(image)
    if array.ndim == 3 and array.shape[2] in (3, 4):  # RGB(A) -> grey (ITU-R BT.601)
        array = array[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
        array = np.round(array).astype(np.uint8) if np.asarray(image).dtype == np.uint8 else array
    if array.ndim != 2:
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {array.shape}")
    if array.dtype != np.uint8:
        array = np.asarray(array, dtype=np.float64)
        if not np.all(np.isfinite(array)):
            raise ValueError("image holds non-finite values")
        if array.max(initial=0.0) > 1.0:
            raise ValueError("a float image must be in [0, 1] (or pass uint8)")
        array = np.round(array * 255.0).astype(np.uint8)
    return array


def _load_camera(camera, image_shape):
    from nbcalib.camera import CameraModel
    from nbcalib.io.camera_file import load_camera

    if isinstance(camera, CameraModel):
        return camera
    if isinstance(camera, (str, os.PathLike)):
        height, width = image_shape[:2]
        return load_camera(camera, width=width, height=height)
    raise TypeError(f"camera must be a CameraModel or a camera file path, got {type(camera)}")


def _keyword_settings() -> dict[str, str]:
    """Setting names that are unique across the config's sections -> ``section.field``."""
    from nbcalib.config import SECTIONS, renamed_settings

    seen: dict[str, list[str]] = {}
    for section, cls in SECTIONS.items():
        for f in fields(cls):
            seen.setdefault(f.name, []).append(f"{section}.{f.name}")
    names = {name: paths[0] for name, paths in seen.items() if len(paths) == 1}
    names["seed"] = "seed"
    for old, new in renamed_settings().items():  # former names still work
        names.setdefault(old.partition(".")[2], new)
    return names


def calibrate(
    points,
    intensities,
    image,
    camera,
    *,
    T_init=None,
    rig=None,
    workdir: str | os.PathLike | None = None,
    config=None,
    model_dir: str | os.PathLike | None = None,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
    **settings,
) -> CalibrationResult:
    """Calibrate a LiDAR-camera pair (or several) from arrays or files.

    Parameters
    ----------
    points : ndarray of shape (N, 3) or (N, 4), float, or str, or a list of them
        Point cloud in the LiDAR frame, metres (a dense cloud or one scan; a LiDAR at rest),
        or a point cloud file (``.pcd``, ``.ply``, ``.bin``, ``.npy``, ``.npz``). A list gives
        several pairs, which share the extrinsic.
    intensities : ndarray of shape (N,), float, or None, or a list of them
        LiDAR intensities, any scale (rank-equalised here); None when ``points`` is a file or
        has intensity as its fourth column.
    image : ndarray of shape (H, W) or (H, W, 3), uint8 or float in [0, 1], or str, or a list
        The camera image (or its file). Several cameras: a dict ``{camera name: image (or a
        list, one per cloud)}``, with ``camera`` a dict of the same names.
    camera : CameraModel or str, or a dict of them
        The camera, or a camera file (ROS camera_info YAML, OpenCV/nbcalib YAML/JSON,
        ``calib.json``); by camera name for several cameras.
    T_init : array_like of shape (4, 4), or Start, optional
        Start of fine registration, ``p_camera = T_init @ p_lidar``, or a
        :class:`~nbcalib.products.Start` (a pose by its seven ``calib.json`` numbers, as
        ``--init`` takes it); default: the automatic guess from keypoint matches.
    rig : Rig or str or os.PathLike, optional
        Several cameras only: their known camera-to-camera extrinsics
        (:class:`nbcalib.io.rig.Rig`, or a Kalibr camchain or nbcalib rig file), named as the
        cameras: one rig pose from every camera (:mod:`nbcalib.rig_pipeline`); ``T_init`` is
        then the first camera's start.
    workdir : str or os.PathLike, optional
        Keep the work directory here (``calib.json`` gets the results); default: in memory.
    config : CalibrationConfig, optional
        Every setting (:mod:`nbcalib.config`); default: the defaults.
    model_dir : str or os.PathLike, optional
        Exported matcher models (default: ``$NBCALIB_MODEL_DIR`` or the user cache).
    progress : bool, optional
        Show the progress as the command line does: a line per stage and a bar for each long
        step, in a notebook as text outputs that update in place, on a terminal on standard
        error. By default (None) it is shown in a notebook or on a terminal unless logging was
        configured (a level for the ``nbcalib`` logger, or a handler such as
        ``logging.basicConfig``'s: then the lines go to that log). True: shown on standard error
        also when it is not a terminal; False: nothing.
    log : callable, optional
        Receives each progress line instead (``log=print``, ``log=lines.append``).
    **settings
        Settings by their name in the config (``voxel_size=0.01``, ``matcher="sift"``,
        ``optimizer="lbfgs"``, ``bins=16``, ``max_outer=5``, ``seed=3``...): any field of a
        section of :class:`~nbcalib.config.CalibrationConfig` whose name no other section
        uses; set the others through ``config``.

    Returns
    -------
    CalibrationResult
        Or, for several cameras, a :class:`nbcalib.rig_pipeline.RigResult` (each camera's
        result, the camera-to-camera transforms).

    Raises
    ------
    InputError
        A missing or corrupt file, or an automatic guess without enough inliers (pass
        ``T_init`` then).
    ValueError
        Arrays of the wrong shape, or an unknown or out-of-range setting.
    """
    from nbcalib.config import CalibrationConfig, set_values
    from nbcalib.pipeline import Calibrator
    from nbcalib.products import Start

    known = _keyword_settings()
    unknown = sorted(set(settings) - set(known))
    if unknown:
        raise ValueError(
            f"unknown setting(s) {', '.join(unknown)}: use a field name of nbcalib.config's "
            "sections, or pass config=CalibrationConfig(...)"
        )
    config = set_values(config or CalibrationConfig(), {known[k]: v for k, v in settings.items()})
    if isinstance(image, dict) or isinstance(camera, dict):
        return _calibrate_cameras(
            points,
            intensities,
            image,
            camera,
            config,
            rig,
            T_init,
            workdir,
            model_dir,
            progress,
            log,
        )
    if rig is not None:
        raise ValueError("rig is for several cameras: give image and camera by camera name")
    clouds, values = _clouds(points, intensities)
    images = _as_list(image, "image")
    if not len(clouds) == len(values) == len(images):
        raise ValueError(
            f"one image and one intensity array per cloud: got {len(clouds)} clouds, "
            f"{len(values)} intensity arrays, {len(images)} images"
        )
    start = T_init
    if T_init is not None and not isinstance(T_init, Start):
        start = Start.from_matrix(T_init, "T_init")
    calibrator = Calibrator(config, workdir=workdir, model_dir=model_dir)
    with api_output(progress, log):
        compiling_note()
        return calibrator.run(ArrayInputs(clouds, values, images, camera), init=start)


def _calibrate_cameras(
    points, intensities, images, cameras, config, rig, T_init, workdir, model_dir, progress, log
):
    """Several cameras (images and cameras by name): :class:`nbcalib.rig_pipeline.RigCalibrator`.

    With a rig, ``T_init`` is the rig's start (the first camera's), and no camera is matched.
    """
    from nbcalib.products import Start
    from nbcalib.rig_pipeline import CameraSource, RigCalibrator

    if not (isinstance(images, dict) and isinstance(cameras, dict)):
        raise ValueError("several cameras: give both image and camera as {camera name: ...}")
    if set(images) != set(cameras) or not images:
        raise ValueError(
            f"image and camera must name the same cameras: {sorted(images)} vs {sorted(cameras)}"
        )
    if T_init is not None and rig is None:
        raise ValueError(
            "T_init with several cameras needs their rig: it is the rig's start (the first "
            "camera's T_camera_lidar)"
        )
    if rig is not None and not hasattr(rig, "cameras"):
        from nbcalib.io.rig import read_rig

        rig = read_rig(rig)
    start = T_init
    if T_init is not None and not isinstance(T_init, Start):
        start = Start.from_matrix(T_init, "T_init")
    clouds, values = _clouds(points, intensities)
    inputs = {}
    for name in images:
        shots = _as_list(images[name], f"image {name!r}")
        if not len(clouds) == len(values) == len(shots):
            raise ValueError(
                f"camera {name!r}: one image and one intensity array per cloud: got "
                f"{len(clouds)} clouds, {len(values)} intensity arrays, {len(shots)} images"
            )
        inputs[name] = ArrayInputs(clouds, values, shots, cameras[name])
    sources = [CameraSource(name, "") for name in images]
    job = RigCalibrator(config, workdir=workdir, model_dir=model_dir, rig=rig)
    with api_output(progress, log):
        compiling_note()
        return job.run(inputs, sources, init=start, no_matching=start is not None)
