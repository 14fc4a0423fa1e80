"""Preprocessing as one step: inputs -> dense clouds -> LiDAR images -> a work directory.

The reference toolbox's ``preprocess`` (bags) and ``preprocess_map`` (plain files) in one
function, without ROS:

1. gather each pair's inputs: a bag gives its point clouds, its first image and its camera info;
   plain files give point clouds in time order and one image;
2. accumulate each pair's scans into a dense cloud: static (LiDAR at rest, non-repetitive scan) or
   dynamic (continuous-time ICP for a moving spinning LiDAR); ``auto`` picks dynamic when the
   scans cover more than 180 degrees of azimuth and there are several of them;
3. equalise LiDAR intensities (rank) and the camera image (histogram), both optional;
4. choose one virtual camera from the first pair's field of view and render every pair's LiDAR
   intensity image and index map;
5. write the work directory (products first, ``calib.json`` last).
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.errors import InputError

__all__ = [
    "CLOUD_SUFFIXES",
    "IMAGE_SUFFIXES",
    "PairInput",
    "PreprocessConfig",
    "classify_inputs",
    "gather_bag",
    "gather_files",
    "preprocess",
]

CLOUD_SUFFIXES = (".pcd", ".ply", ".bin", ".npy", ".npz")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
BAG_SUFFIXES = (".bag", ".db3", ".mcap")


@dataclass(frozen=True)
class PreprocessConfig:
    """Settings of :func:`preprocess` (defaults as the reference toolbox's CLI where it has one).

    Attributes
    ----------
    mode : {"auto", "static", "dynamic"}
        How scans become a dense cloud (module docstring).
    voxel_size : float
        Output voxel of the dense cloud, metres (reference: 0.002).
    min_distance : float
        Points nearer than this to the sensor are dropped, metres (reference: 1.0).
    frame_rate : float
        Scans per second, for synthesising per-point times of files that carry none (Hz).
    equalize_intensities, equalize_image : bool
        Rank-equalise LiDAR intensities / histogram-equalise the camera image (paper III-C).
    intensity_channel : str
        ``"auto"`` (``reflectivity`` over ``intensity``) or a field name.
    points_topic, image_topic, camera_info_topic : str or None
        Bag topics; None picks the only topic of the kind.
    max_scans : int or None
        Use at most this many scans per pair.
    """

    mode: str = "auto"
    voxel_size: float = 0.002
    min_distance: float = 1.0
    frame_rate: float = 10.0
    equalize_intensities: bool = True
    equalize_image: bool = True
    intensity_channel: str = "auto"
    points_topic: str | None = None
    image_topic: str | None = None
    camera_info_topic: str | None = None
    max_scans: int | None = None

    def __post_init__(self):
        if self.mode not in ("auto", "static", "dynamic"):
            raise InputError(f"mode must be auto, static or dynamic, got {self.mode!r}")
        if not (self.voxel_size > 0 and math.isfinite(self.voxel_size)):
            raise InputError(f"voxel size must be a positive number, got {self.voxel_size}")
        if not self.min_distance >= 0:
            raise InputError(f"min distance must be >= 0, got {self.min_distance}")
        if not self.frame_rate > 0:
            raise InputError(f"frame rate must be > 0, got {self.frame_rate}")
        if self.max_scans is not None and self.max_scans < 1:
            raise InputError(f"max scans must be >= 1, got {self.max_scans}")


@dataclass
class PairInput:
    """What one pair is made from: scans in time order, one image, and where they came from."""

    name: str
    scans: list
    image: np.ndarray
    image_source: str
    camera: CameraModel | None = None
    topics: dict[str, str] = field(default_factory=dict)


def classify_inputs(
    paths: Sequence[str | os.PathLike],
) -> tuple[list[Path], list[Path], list[Path]]:
    """Split input paths into (bags, point cloud files, image files) by suffix / folder layout."""
    bags, clouds, images = [], [], []
    for raw in paths:
        p = Path(raw)
        suffix = p.suffix.lower()
        if p.is_dir() or suffix in BAG_SUFFIXES:
            bags.append(p)
        elif suffix in CLOUD_SUFFIXES:
            clouds.append(p)
        elif suffix in IMAGE_SUFFIXES:
            images.append(p)
        elif not p.exists():
            raise InputError("no such file or folder", path=p)
        else:
            raise InputError(
                f"unknown input type '{suffix}': expected a bag (.bag, ROS 2 folder, .db3, .mcap), "
                f"a point cloud ({', '.join(CLOUD_SUFFIXES)}) or an image "
                f"({', '.join(IMAGE_SUFFIXES)})",
                path=p,
            )
    return bags, clouds, images


def _bag_name(path: Path) -> str:
    # the reference keeps the .bag suffix of ROS 1 bags and uses a ROS 2 folder's name
    return (
        path.name if path.suffix.lower() == ".bag" else (path.stem if path.is_file() else path.name)
    )


def gather_bag(path, config: PreprocessConfig) -> PairInput:
    """Read one bag: every point cloud of the points topic, the first image, the camera info."""
    from nbcalib.io.bag import open_bag

    path = Path(path)
    with open_bag(path) as bag:
        points_topic = bag.select_topic("point cloud", config.points_topic)
        image_topic = bag.select_topic("image", config.image_topic)
        camera = None
        try:
            info_topic = bag.select_topic("camera info", config.camera_info_topic)
            camera = bag.camera_info(info_topic)
        except InputError:
            if config.camera_info_topic is not None:
                raise
            info_topic = "N/A"
        image = None
        for _, img in bag.images(image_topic, grey=True):
            image = img
            break
        if image is None:
            raise InputError(f"image topic {image_topic} has no messages", path=path)
        scans = []
        for _, cloud in bag.pointclouds(points_topic, intensity_channel=config.intensity_channel):
            scans.append(cloud)
            if config.max_scans is not None and len(scans) >= config.max_scans:
                break
    if not scans:
        raise InputError(f"point cloud topic {points_topic} has no messages", path=path)
    topics = {
        "points_topic": points_topic,
        "image_topic": image_topic,
        "camera_info_topic": info_topic,
    }
    return PairInput(_bag_name(path), scans, image, f"{path} {image_topic}", camera, topics)


def gather_files(cloud_paths, image_path, config: PreprocessConfig, *, name: str = "000000"):
    """Plain files: point clouds in the given (time) order and one image."""
    from nbcalib.io.image import read_image
    from nbcalib.io.pointcloud import read_pointcloud

    if not cloud_paths:
        raise InputError("no point cloud file given (.pcd, .ply, .bin, .npy, .npz)")
    paths = [Path(p) for p in cloud_paths]
    if config.max_scans is not None:
        paths = paths[: config.max_scans]
    channel = config.intensity_channel
    scans = [read_pointcloud(p, intensity_channel=channel) for p in paths]
    image_path = Path(image_path)
    if not image_path.is_file():
        raise InputError("image not found", path=image_path)
    image = read_image(image_path, grey=True)
    return PairInput(name, scans, image, str(image_path))


def _azimuth_coverage_deg(points: np.ndarray) -> float:
    az = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return float(np.unique(np.floor(az).astype(np.int64)).size)


def _choose_mode(pair: PairInput, config: PreprocessConfig) -> str:
    if config.mode != "auto":
        return config.mode
    if len(pair.scans) < 2:
        return "static"
    return "dynamic" if _azimuth_coverage_deg(pair.scans[0].points) > 180 else "static"


def _check_scans(pair: PairInput) -> None:
    for i, scan in enumerate(pair.scans):
        if scan.points.shape[0] == 0:
            raise InputError(f"scan {i} of pair '{pair.name}' holds no finite point")
    if all(scan.intensity is None for scan in pair.scans):
        raise InputError(
            f"the point clouds of pair '{pair.name}' have no intensity field "
            "(choose one with the intensity channel option)"
        )


def _to_uint8(image: np.ndarray) -> np.ndarray:
    if image.dtype == np.uint8:
        return image
    from nbcalib.io.image import to_float_grey

    return np.round(to_float_grey(image) * 255.0).astype(np.uint8)


def _accumulate(pair: PairInput, mode: str, config: PreprocessConfig, progress):
    from nbcalib.odometry import integrate_dynamic
    from nbcalib.preprocess.accumulate import integrate_static

    if mode == "static":
        return integrate_static(
            pair.scans,
            voxel_size=config.voxel_size,
            min_distance=config.min_distance,
            progress=progress,
        )
    return integrate_dynamic(
        pair.scans,
        voxel_size=config.voxel_size,
        min_distance=config.min_distance,
        frame_rate=config.frame_rate,
        progress=progress,
    )


def preprocess(
    pairs: Sequence[PairInput],
    workdir,
    *,
    camera: CameraModel | None = None,
    config: PreprocessConfig | None = None,
    data_path: str = "",
    log: Callable[[str], None] | None = None,
) -> dict:
    """Turn pairs of inputs into a work directory (module docstring); returns a summary.

    Parameters
    ----------
    pairs : sequence of PairInput
        From :func:`gather_bag` / :func:`gather_files`.
    workdir : str or os.PathLike
        Output folder (created; an existing ``calib.json`` there is removed first).
    camera : CameraModel, optional
        The camera; default: the first pair's camera info. Every pair must agree with it.
    config : PreprocessConfig, optional
    data_path : str
        Recorded as ``meta.data_path``.
    log : callable, optional
        Receives progress lines (default: stderr).
    """
    from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities
    from nbcalib.preprocess.lidar_image import (
        estimate_lidar_fov,
        make_virtual_camera,
        render_lidar_image,
    )
    from nbcalib.workdir import WorkDir, make_calib, set_virtual_camera

    config = config or PreprocessConfig()
    log = log or (lambda line: print(line, file=sys.stderr))
    if not pairs:
        raise InputError("nothing to preprocess: no bag and no point cloud given")
    camera = camera or pairs[0].camera
    if camera is None:
        raise InputError(
            f"{pairs[0].name}: no camera info found; give the camera with --camera FILE or "
            "--camera-model/--intrinsics/--distortion"
        )
    names = [p.name for p in pairs]
    if len(set(names)) != len(names):
        raise InputError(f"two inputs have the same name: {names}")
    for pair in pairs:
        if (
            pair.camera is not None
            and pairs[0].camera is not None
            and pair.camera != pairs[0].camera
        ):
            raise InputError(
                f"pair '{pair.name}' has another camera than '{pairs[0].name}' "
                "(mixed sensors across bags?)"
            )
        h, w = pair.image.shape[:2]
        if (w, h) != (camera.width, camera.height):
            raise InputError(
                f"the image is {w} x {h} but the camera is {camera.width} x {camera.height}",
                path=pair.image_source,
            )
        _check_scans(pair)

    work = WorkDir(workdir)
    work.prepare()
    t_start = time.perf_counter()
    summary: dict = {"pairs": {}}
    vcam = T_vcam_lidar = None
    for k, pair in enumerate(pairs):
        mode = _choose_mode(pair, config)
        log(f"[{k + 1}/{len(pairs)}] {pair.name}: {len(pair.scans)} scan(s), {mode} integration")
        t0 = time.perf_counter()
        cloud = _accumulate(pair, mode, config, progress=len(pair.scans) > 3)
        if len(cloud) == 0:
            raise InputError(
                f"pair '{pair.name}': no point left after accumulation "
                f"(all within {config.min_distance} m of the sensor?)"
            )
        intensities = cloud.intensity
        if config.equalize_intensities:
            intensities = equalize_point_intensities(intensities)
        else:
            top = float(np.max(intensities)) if intensities.size else 1.0
            intensities = np.clip(intensities / (top if top > 0 else 1.0), 0.0, 1.0)
        image = equalize_image(pair.image) if config.equalize_image else _to_uint8(pair.image)
        if vcam is None:  # one virtual camera for all pairs, from the first pair (reference)
            fov = estimate_lidar_fov(cloud.points)
            vcam, T_vcam_lidar = make_virtual_camera(fov)
            summary["lidar_fov_deg"] = math.degrees(fov)
            log(f"    LiDAR field of view {math.degrees(fov):.1f} deg: {vcam.model} virtual camera")
        lidar_image = render_lidar_image(vcam, T_vcam_lidar, cloud.points, intensities)
        work.write_pair(
            pair.name,
            image=image,
            points_lidar=cloud.points,
            intensities=intensities,
            lidar_image=lidar_image,
        )
        filled = int((lidar_image.index >= 0).sum())
        log(
            f"    {len(cloud)} points, LiDAR image {filled} filled pixels, "
            f"{time.perf_counter() - t0:.1f} s"
        )
        summary["pairs"][pair.name] = {
            "mode": mode,
            "scans": len(pair.scans),
            "points": len(cloud),
            "lidar_image_filled_pixels": filled,
        }
    topics = pairs[0].topics
    calib = make_calib(
        camera,
        names,
        data_path=data_path,
        camera_info_topic=topics.get("camera_info_topic", "N/A"),
        image_topic=topics.get("image_topic", "N/A"),
        points_topic=topics.get("points_topic", "N/A"),
        intensity_channel=config.intensity_channel,
    )
    set_virtual_camera(calib, vcam, T_vcam_lidar)
    summary["seconds"] = round(time.perf_counter() - t_start, 3)
    summary["config"] = {
        "mode": config.mode,
        "voxel_size": config.voxel_size,
        "min_distance": config.min_distance,
        "frame_rate": config.frame_rate,
        "equalize_intensities": config.equalize_intensities,
        "equalize_image": config.equalize_image,
    }
    calib.nbcalib["preprocess"] = summary
    work.write_calib(calib)
    return summary
