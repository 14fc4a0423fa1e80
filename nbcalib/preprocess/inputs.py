"""What a calibration is made from: bags or plain files, gathered into pairs of scans + image.

The reference toolbox's ``preprocess`` (bags) and ``preprocess_map`` (plain files) take their
inputs in two forms, and so does nbcalib, without ROS:

- **bags** (ROS 1 ``.bag``, ROS 2 folders with sqlite3 or mcap): each bag is one pair, its point
  clouds in time order, its first image and its camera info (:func:`gather_bag`);
- **plain files**: point clouds (``.pcd``, ``.ply``, KITTI ``.bin``, ``.npy``/``.npz``) in time
  order and one image (:func:`gather_files`).

Both make one pair of all their scans, the image taken at the start of the first scan (the
reference's collection procedure: the rig at rest at first). Several pairs from one recording,
one per image with the scans around it and the cloud at the image's time, come from a folder of
frames (``frames``), scans with several images (``images``), or bags with an image selection
(``every``, ``pair_count``, ``image_times``): :mod:`nbcalib.preprocess.recording`.

:class:`InputSpec` is the user's description of the inputs (paths and camera options, as typed
on the command line); :meth:`InputSpec.gather` reads them into :class:`PairInput` objects and
resolves the camera. The spec is recorded in the work directory, so that ``nbcalib run WORKDIR``
can continue a job with the inputs it was started with.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from nbcalib._threads import thread_map
from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.preprocess.config import PreprocessConfig

__all__ = [
    "BAG_SUFFIXES",
    "CLOUD_SUFFIXES",
    "IMAGE_SUFFIXES",
    "InputSpec",
    "PairInput",
    "SharedClouds",
    "classify_inputs",
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


def gather_bag(path, config: PreprocessConfig) -> PairInput:
    """Read one bag: every point cloud of the points topic, the first image, the camera info."""
    from nbcalib.io.bag import open_bag

    path = Path(path)
    with open_bag(path) as bag:
        points_topic, image_topic, info_topic, camera = bag_topics(bag, config, path)
        image = first_image(bag, image_topic, path)
        scans = bag_scans(bag, points_topic, config, path)
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


def _numbers(text: str | None, option: str) -> list[float]:
    if text is None or str(text).strip() == "":
        return []
    try:
        return [float(v) for v in str(text).split(",")]
    except ValueError:
        raise InputError(f"{option} must be comma-separated numbers, got {text!r}") from None


#: InputSpec fields of the per-image forms, recorded only when given (to_dict)
_RECORDING_FIELDS = ("frames", "images", "image_times", "scan_times", "every", "pair_count")


def _check_all_scans(config: PreprocessConfig, what: str) -> None:
    """A pair of all its scans has no neighbours to choose: refuse ``neighbors`` other than 1."""
    if config.neighbors != 1:
        raise InputError(
            f"neighbors={config.neighbors}: {what} makes one pair of all its scans (at most "
            "--max-scans); scans around an image are for pairs per image (--frames, --images, "
            "or a bag's --every/--pair-count/--image-times)"
        )


#: The camera option a camera parameter error is about, by a word of its message.
_CAMERA_OPTION_WORDS = (
    ("--distortion", "distortion"),
    ("--intrinsics", "intrinsics"),
    ("--camera-model", "model"),
)


@dataclass(frozen=True)
class InputSpec:
    """The inputs of a job as the user gives them (command line: ``INPUT...``, ``--points``...).

    Attributes
    ----------
    inputs : tuple of str
        Bags, or point cloud files and one image.
    points : tuple of str
        More point cloud files (``--points``).
    image : str or None
        The image for ``points`` (``--image``).
    camera : str or None
        A camera file: ROS camera_info YAML, nbcalib/OpenCV camera YAML/JSON, or a calib.json.
    camera_model, intrinsics, distortion : str or None
        The camera by its parameters (``plumb_bob``, ``fx,fy,cx,cy``, ``k1,k2,...``).
    frames : str or None
        A folder of frames, one pair each (``--frames``, :func:`~nbcalib.preprocess.recording.
        gather_frames`).
    images : tuple of str
        Several images for the point clouds, one pair each (``--images``).
    image_times : str or None
        ``a,b,...`` seconds or a file of times: the times of ``images``, or for bags the header
        stamps to make pairs at (``--image-times``).
    scan_times : str or None
        The times at which the point clouds of ``images`` begin (``--scan-times``; default
        ``k / frame_rate``).
    every : int or None
        Pairs at every Nth image of the recording (``--every``).
    pair_count : int or None
        N pairs, their images spread evenly over the recording (``--pair-count``).
    """

    inputs: tuple[str, ...] = ()
    points: tuple[str, ...] = ()
    image: str | None = None
    camera: str | None = None
    camera_model: str | None = None
    intrinsics: str | None = None
    distortion: str | None = None
    frames: str | None = None
    images: tuple[str, ...] = ()
    image_times: str | None = None
    scan_times: str | None = None
    every: int | None = None
    pair_count: int | None = None

    def __post_init__(self):
        object.__setattr__(self, "inputs", tuple(str(p) for p in self.inputs))
        object.__setattr__(self, "points", tuple(str(p) for p in self.points))
        object.__setattr__(self, "images", tuple(str(p) for p in self.images))
        for name in ("frames", "image_times", "scan_times"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, str(value))
        for name, flag in (("every", "--every"), ("pair_count", "--pair-count")):
            value = getattr(self, name)
            if value is None:
                continue
            try:
                number = int(value)
            except (TypeError, ValueError):
                number = None
            if number is None or number != float(value) or number < 1:
                raise InputError(f"{flag} must be a whole number >= 1, got {value!r}")
            object.__setattr__(self, name, number)
        if self.every is not None and self.pair_count is not None:
            raise InputError("give --every or --pair-count, not both")

    @property
    def empty(self) -> bool:
        """No input at all."""
        return not (self.inputs or self.points or self.frames or self.images)

    @property
    def per_image(self) -> bool:
        """Pairs are made per image of a recording (:mod:`nbcalib.preprocess.recording`)."""
        return bool(
            self.frames
            or self.images
            or self.image_times is not None
            or self.scan_times is not None
            or self.every is not None
            or self.pair_count is not None
        )

    def to_dict(self) -> dict:
        """JSON-ready form with absolute paths (:meth:`from_dict` reads it back).

        Absolute, so that a job continued from another folder finds its inputs, and the same
        inputs typed from another folder are recognised as the same. The recording options
        (``frames`` ... ``pair_count``) appear only when given, so that a job recorded before
        they existed is recognised as the same job.
        """

        def absolute(path):
            return None if path is None else str(Path(path).absolute())

        data = {
            key: value
            for key, value in asdict(self).items()
            if key not in _RECORDING_FIELDS or value not in (None, ())
        }
        data["inputs"] = [absolute(p) for p in self.inputs]
        data["points"] = [absolute(p) for p in self.points]
        data["image"], data["camera"] = absolute(self.image), absolute(self.camera)
        if self.frames is not None:
            data["frames"] = absolute(self.frames)
        if self.images:
            data["images"] = [absolute(p) for p in self.images]
        for key in ("image_times", "scan_times"):  # a file of times, or the numbers themselves
            value = getattr(self, key)
            if value is not None and Path(value).is_file():
                data[key] = absolute(value)
        return data

    @classmethod
    def from_dict(cls, data: dict) -> InputSpec:
        """Inverse of :meth:`to_dict`; unknown keys are ignored."""
        known = {k: data[k] for k in cls.__dataclass_fields__ if data.get(k) is not None}
        return cls(**known)

    def gather(self, config: PreprocessConfig) -> tuple[list[PairInput], CameraModel, str]:
        """Read the inputs: (pairs, camera, data_path).

        Raises
        ------
        InputError
            Missing, unknown or corrupt inputs, bags mixed with plain files, not exactly one
            image for plain files, recording options that do not fit the inputs, or no camera
            (the message says which option gives one).
        """
        bags, clouds, images = classify_inputs(self.inputs)
        clouds += [Path(p) for p in self.points]
        if self.image:
            images.append(Path(self.image))
        if bags and (clouds or images):
            raise InputError("give either bags or plain files (point clouds + image), not both")
        if self.per_image:
            pairs, data_path = self._gather_per_image(bags, clouds, images, config)
        elif bags:
            _check_all_scans(config, "a bag without --every, --pair-count or --image-times")
            bags = sorted(bags, key=lambda p: p.name)  # read on every core (nbcalib._threads)
            pairs = thread_map(lambda bag: gather_bag(bag, config), bags)
            data_path = str(Path(bags[0]).resolve().parent)
        else:
            if len(images) != 1:
                raise InputError(
                    f"plain files need exactly one image (.png/.jpg), got {len(images)}"
                    + ("; for one pair per image give them with --images" if images else "")
                    + ("" if images else "; add --image FILE")
                )
            _check_all_scans(config, "plain files with one image")
            pairs = [gather_files(clouds, images[0], config)]
            data_path = str(Path(clouds[0]).resolve().parent) if clouds else ""
        try:
            camera = self.camera_for(pairs[0].image.shape) or pairs[0].camera
        except InputError as exc:
            source = pairs[0].image_source
            if source is None or "images, not" not in str(exc):
                raise
            # a camera of another size: the image may be the wrong one, so name it too
            raise InputError(f"{Path(source).name} does not fit the camera: {exc}") from None
        if camera is None:
            raise InputError(
                f"{pairs[0].name}: no camera info found; give the camera with --camera FILE or "
                "--camera-model/--intrinsics/--distortion"
            )
        return pairs, camera, data_path

    def _gather_per_image(self, bags, clouds, images, config) -> tuple[list[PairInput], str]:
        """Pairs per image of a recording (:mod:`nbcalib.preprocess.recording`)."""
        from nbcalib.preprocess import recording

        select = {"every": self.every, "pair_count": self.pair_count}
        if self.frames:
            if bags or clouds or images or self.images:
                raise InputError("--frames takes the whole recording: give no other input")
            if self.image_times is not None or self.scan_times is not None:
                raise InputError("--image-times/--scan-times do not apply to --frames")
            pairs = recording.gather_frames(self.frames, config, **select)
            return pairs, str(Path(self.frames).resolve())
        if bags:
            if self.images or self.scan_times is not None:
                raise InputError("--images/--scan-times are for plain point cloud files, not bags")
            if self.image_times is not None and (self.every or self.pair_count):
                raise InputError("give --image-times, --every or --pair-count, not several")
            pairs = []
            for bag in sorted(bags, key=lambda p: p.name):
                pairs += recording.gather_bag_pairs(
                    bag, config, image_times=self.image_times, **select
                )
            return pairs, str(Path(bags[0]).resolve().parent)
        if not self.images:
            raise InputError(
                "--every, --pair-count, --image-times and --scan-times are for several "
                "images: give --frames DIR, --images FILE..., or a bag"
            )
        if images:
            raise InputError("give the images of a sequence all with --images (none as INPUT)")
        for path in self.images:
            if Path(path).suffix.lower() not in IMAGE_SUFFIXES:
                raise InputError(f"--images takes images ({', '.join(IMAGE_SUFFIXES)})", path=path)
        pairs = recording.gather_image_sequence(
            clouds,
            self.images,
            config,
            image_times=self.image_times,
            scan_times=self.scan_times,
            **select,
        )
        return pairs, str(Path(clouds[0]).resolve().parent)

    def camera_for(self, image_shape) -> CameraModel | None:
        """The camera the spec names (a file or parameters), sized like the image; else None."""
        from nbcalib.camera import canonical_model_name, create_camera
        from nbcalib.io.camera_file import load_camera

        height, width = image_shape[:2]
        if self.camera:
            return load_camera(self.camera, width=width, height=height)
        if not self.camera_model:
            if self.intrinsics or self.distortion:
                raise InputError("--intrinsics/--distortion need --camera-model")
            return None
        try:
            model = canonical_model_name(self.camera_model)
            intrinsics = _numbers(self.intrinsics, "--intrinsics")
            if model == "equirectangular" and not intrinsics:
                intrinsics = [width, height]  # as the reference: the image size
            distortion = _numbers(self.distortion, "--distortion")
            return create_camera(model, intrinsics, distortion, width, height)
        except ValueError as exc:
            text = str(exc)
            if text.startswith("--"):
                raise InputError(text) from None
            option = next(
                (f for f, word in _CAMERA_OPTION_WORDS if word in text),
                "--camera-model/--intrinsics/--distortion",
            )
            raise InputError(f"{option}: {text}") from None
