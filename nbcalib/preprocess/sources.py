"""One source of a calibration read into a pair: a bag, or plain files (scans + one image).

The readers below every form of input: :func:`gather_bag` (a bag's scans, its first image and
camera info), :func:`gather_files` (point cloud files in time order and one image),
:func:`read_scan`, and the choice of a bag's topics (:func:`bag_topics`). Pairs per image of a
recording (:mod:`nbcalib.preprocess.recording`) build on them; :class:`InputSpec
<nbcalib.preprocess.inputs.InputSpec>` (the user's description of the inputs) dispatches to
both and sits above them.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.preprocess.config import PreprocessConfig

__all__ = [
    "BAG_SUFFIXES",
    "CLOUD_SUFFIXES",
    "IMAGE_SUFFIXES",
    "PLAIN_FILES_NAME",
    "DeferredScans",
    "PairInput",
    "SharedClouds",
    "bag_name",
    "bag_scans",
    "bag_topics",
    "classify_inputs",
    "first_image",
    "gather_bag",
    "gather_files",
    "read_scan",
]

CLOUD_SUFFIXES = (".pcd", ".ply", ".bin", ".npy", ".npz")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
BAG_SUFFIXES = (".bag", ".db3", ".mcap")

#: Data name of a pair of plain files (as the reference's ``preprocess_map``).
PLAIN_FILES_NAME = "000000"


@dataclass
class PairInput:
    """What one pair is made from: scans in time order, one image, and where they came from.

    Attributes
    ----------
    name : str
        Data name (a bag's name, or ``000000``).
    scans : list of PointCloud
        The scans (:class:`nbcalib.io.pointcloud.PointCloud`), in time order.
    image : ndarray of shape (H, W), uint8 or float
        The camera image, grey.
    image_source : str
        Where the image came from, for messages.
    camera : CameraModel or None
        The camera info of a bag.
    topics : dict of str to str
        The bag topics used (``points_topic``, ``image_topic``, ``camera_info_topic``).
    image_scan : int or None
        The scan (index into ``scans``) taken while the image was taken, for pairs made per
        image (:mod:`nbcalib.preprocess.recording`): the dense cloud is expressed in the LiDAR
        frame at the image's time. None: at the start of the first scan (a pair of all its
        scans).
    image_fraction : float
        The image's time as a fraction of that scan's sweep (0 = its first point, 1 = its last).
    info : dict
        Where the pair sits in its recording (``first_scan``, ``image_scan``, ...), for the
        work directory's summary.
    clouds : SharedClouds or None
        Dense clouds made of ``scans``, shared by the pairs of several cameras that hold the
        same scans (:mod:`nbcalib.rig_pipeline`): accumulated once, for the first camera that
        asks (:func:`~nbcalib.preprocess.prepare.prepare_pair`). None: not shared.
    """

    name: str
    scans: list
    image: np.ndarray
    image_source: str
    camera: CameraModel | None = None
    topics: dict[str, str] = field(default_factory=dict)
    image_scan: int | None = None
    image_fraction: float = 0.0
    info: dict = field(default_factory=dict)
    clouds: SharedClouds | None = field(default=None, repr=False)


class SharedClouds:
    """The dense clouds of one pair's scans, made once for every camera (thread-safe)."""

    def __init__(self):
        import threading

        self._clouds: dict = {}
        self._lock = threading.Lock()

    def get(self, key, make):
        """The cloud made under ``key``; ``make()`` makes it the first time (once)."""
        with self._lock:
            if key not in self._clouds:
                self._clouds[key] = make()
            return self._clouds[key]


def classify_inputs(
    paths: Sequence[str | os.PathLike],
) -> tuple[list[Path], list[Path], list[Path]]:
    """Split input paths into (bags, point cloud files, image files) by suffix / folder layout."""
    bags, clouds, images = [], [], []
    for raw in paths:
        p = Path(raw)
        suffix = p.suffix.lower()
        if suffix in BAG_SUFFIXES or (p.is_dir() and suffix not in CLOUD_SUFFIXES + IMAGE_SUFFIXES):
            bags.append(p)  # a folder named like a cloud or image goes on, to be refused by name
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


def bag_name(path: Path) -> str:
    """A bag's data name: the reference keeps a ROS 1 bag's ``.bag`` suffix, a folder's name."""
    path = Path(path)
    if path.suffix.lower() == ".bag":
        return path.name
    return path.stem if path.is_file() else path.name


def bag_topics(bag, config: PreprocessConfig, path) -> tuple[str, str, str, CameraModel | None]:
    """(points topic, image topic, camera info topic or ``N/A``, camera or None) of a bag."""
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
    return points_topic, image_topic, info_topic, camera


class DeferredScans(Sequence):
    """A pair's scans, read when first asked for and dropped again by :meth:`release`.

    A job of many bags holds one bag's scans at a time per core instead of every bag's: the
    topics, the first image and the number of scans are read when the bag is gathered, the
    scans when the pair is prepared (:func:`nbcalib.preprocess.prepare.prepare_pair`, which
    checks them then).
    """

    #: Read later: :func:`~nbcalib.preprocess.prepare.check_pairs` leaves them to the pair.
    deferred = True

    def __init__(self, read: Callable[[], list], count: int):
        import threading

        self._read = read
        self._count = int(count)
        self._scans: list | None = None
        self._lock = threading.Lock()

    def __repr__(self) -> str:
        return f"DeferredScans({self._count} scans, {'read' if self._scans else 'not read'})"

    def _held(self) -> list:
        with self._lock:
            if self._scans is None:
                self._scans = self._read()
            return self._scans

    def __len__(self) -> int:
        return self._count if self._scans is None else len(self._scans)

    def __getitem__(self, index):
        return self._held()[index]

    def __iter__(self):
        return iter(self._held())

    def release(self) -> None:
        """Forget the scans read (they are read again if asked for)."""
        with self._lock:
            self._scans = None


def gather_bag(path, config: PreprocessConfig) -> PairInput:
    """One bag's pair: its topics, first image and camera info now, its scans when needed.

    The scans (every point cloud of the points topic, at most ``config.max_scans``) are a
    :class:`DeferredScans`: read when the pair is prepared.
    """
    from nbcalib.io.bag import open_bag

    path = Path(path)
    with open_bag(path) as bag:
        points_topic, image_topic, info_topic, camera = bag_topics(bag, config, path)
        image = first_image(bag, image_topic, path)
        count = len(bag.stamps(points_topic))
    if count == 0:
        raise InputError(f"point cloud topic {points_topic} has no messages", path=path)
    if config.max_scans is not None:
        count = min(count, config.max_scans)

    def read() -> list:
        with open_bag(path) as again:
            return bag_scans(again, points_topic, config, path)

    scans = DeferredScans(read, count)
    topics = {
        "points_topic": points_topic,
        "image_topic": image_topic,
        "camera_info_topic": info_topic,
    }
    return PairInput(bag_name(path), scans, image, f"{path} {image_topic}", camera, topics)


def first_image(bag, topic: str, path) -> np.ndarray:
    """The first image of ``topic``, grey; InputError when the topic has none."""
    image = next((img for _, img in bag.images(topic, grey=True)), None)
    if image is None:
        raise InputError(f"image topic {topic} has no messages", path=path)
    return image


def bag_scans(bag, topic: str, config: PreprocessConfig, path) -> list:
    """Every point cloud of ``topic`` (at most ``config.max_scans``); InputError when none."""
    scans = []
    for _, cloud in bag.pointclouds(topic, intensity_channel=config.intensity_channel):
        scans.append(cloud)
        if config.max_scans is not None and len(scans) >= config.max_scans:
            break
    if not scans:
        raise InputError(f"point cloud topic {topic} has no messages", path=path)
    return scans


def gather_files(
    cloud_paths, image_path, config: PreprocessConfig, *, name: str = PLAIN_FILES_NAME
) -> PairInput:
    """Plain files: point clouds in the given (time) order and one image."""
    from nbcalib.io.image import read_image

    if not cloud_paths:
        raise InputError("no point cloud file given (.pcd, .ply, .bin, .npy, .npz)")
    paths = [Path(p) for p in cloud_paths]
    if config.max_scans is not None:
        paths = paths[: config.max_scans]
    scans = [read_scan(p, config.intensity_channel) for p in paths]
    image_path = Path(image_path)
    if not image_path.is_file():
        raise InputError("image not found", path=image_path)
    image = read_image(image_path, grey=True)
    return PairInput(name, scans, image, str(image_path))


def read_scan(path, intensity_channel: str | None = "auto"):
    """One point cloud file as a scan; a file of no points is refused.

    Parameters
    ----------
    path : str or os.PathLike
        The file (:func:`nbcalib.io.pointcloud.read_pointcloud`).
    intensity_channel : str or None
        As for :func:`~nbcalib.io.pointcloud.read_pointcloud`.

    Returns
    -------
    PointCloud

    Raises
    ------
    InputError
        The file cannot be read, or holds no (finite) point; the message names the file.
    """
    from nbcalib.io.pointcloud import read_pointcloud

    cloud = read_pointcloud(path, intensity_channel=intensity_channel)
    if not len(cloud):
        raise InputError("holds no points", path=path)
    return cloud
