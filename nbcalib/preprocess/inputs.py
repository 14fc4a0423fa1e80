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

from dataclasses import asdict, dataclass
from pathlib import Path

from nbcalib._threads import thread_map
from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.sources import (  # re-exported: the readers of one source
    BAG_SUFFIXES,
    CLOUD_SUFFIXES,
    IMAGE_SUFFIXES,
    PairInput,
    SharedClouds,
    classify_inputs,
    gather_bag,
    gather_files,
    read_scan,
)

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
            "preprocess.max_scans); scans around an image are for pairs per image "
            "(inputs.frames, inputs.images, or a bag's "
            "inputs.every/inputs.pair_count/inputs.image_times)"
        )


#: The camera option a camera parameter error is about, by a word of its message.
_CAMERA_OPTION_WORDS = (
    ("inputs.distortion", "distortion"),
    ("inputs.intrinsics", "intrinsics"),
    ("inputs.camera_model", "model"),
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
        for name, flag in (("every", "inputs.every"), ("pair_count", "inputs.pair_count")):
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
            raise InputError("give inputs.every or inputs.pair_count, not both")

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
            _check_all_scans(
                config, "a bag without inputs.every, inputs.pair_count or inputs.image_times"
            )
            bags = sorted(bags, key=lambda p: p.name)  # read on every core (nbcalib._threads)
            pairs = thread_map(lambda bag: gather_bag(bag, config), bags)
            data_path = str(Path(bags[0]).resolve().parent)
        else:
            if len(images) != 1:
                raise InputError(
                    f"plain files need exactly one image (.png/.jpg), got {len(images)}"
                    + ("; for one pair per image give them with inputs.images" if images else "")
                    + ("" if images else "; add inputs.image FILE")
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
                f"{pairs[0].name}: no camera info found; give the camera with inputs.camera "
                "FILE or inputs.camera_model/inputs.intrinsics/inputs.distortion"
            )
        return pairs, camera, data_path

    def _gather_per_image(self, bags, clouds, images, config) -> tuple[list[PairInput], str]:
        """Pairs per image of a recording (:mod:`nbcalib.preprocess.recording`)."""
        from nbcalib.preprocess import recording

        select = {"every": self.every, "pair_count": self.pair_count}
        if self.frames:
            if bags or clouds or images or self.images:
                raise InputError("inputs.frames takes the whole recording: give no other input")
            if self.image_times is not None or self.scan_times is not None:
                raise InputError(
                    "inputs.image_times/inputs.scan_times do not apply to inputs.frames"
                )
            pairs = recording.gather_frames(self.frames, config, **select)
            return pairs, str(Path(self.frames).resolve())
        if bags:
            if self.images or self.scan_times is not None:
                raise InputError(
                    "inputs.images/inputs.scan_times are for plain point cloud files, not bags"
                )
            if self.image_times is not None and (self.every or self.pair_count):
                raise InputError(
                    "give inputs.image_times, inputs.every or inputs.pair_count, not several"
                )
            pairs = []
            for bag in sorted(bags, key=lambda p: p.name):
                pairs += recording.gather_bag_pairs(
                    bag, config, image_times=self.image_times, **select
                )
            return pairs, str(Path(bags[0]).resolve().parent)
        if not self.images:
            raise InputError(
                "inputs.every, inputs.pair_count, inputs.image_times and inputs.scan_times are "
                "for several images: give inputs.frames DIR, inputs.images FILE..., or a bag"
            )
        if images:
            raise InputError("give the images of a sequence all with inputs.images (none as INPUT)")
        for path in self.images:
            if Path(path).suffix.lower() not in IMAGE_SUFFIXES:
                raise InputError(
                    f"inputs.images takes images ({', '.join(IMAGE_SUFFIXES)})",
                    path=path,
                )
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
                raise InputError("inputs.intrinsics/inputs.distortion need inputs.camera_model")
            return None
        try:
            model = canonical_model_name(self.camera_model)
            intrinsics = _numbers(self.intrinsics, "inputs.intrinsics")
            if model == "equirectangular" and not intrinsics:
                intrinsics = [width, height]  # as the reference: the image size
            distortion = _numbers(self.distortion, "inputs.distortion")
            return create_camera(model, intrinsics, distortion, width, height)
        except ValueError as exc:
            text = str(exc)
            if text.startswith("--"):
                raise InputError(text) from None
            option = next(
                (f for f, word in _CAMERA_OPTION_WORDS if word in text),
                "inputs.camera_model/inputs.intrinsics/inputs.distortion",
            )
            raise InputError(f"{option}: {text}") from None
