"""Settings of preprocessing (paper section III-C), importable without numba.

:class:`PreprocessConfig` is the ``preprocess`` section of the pipeline's config
(:class:`nbcalib.config.CalibrationConfig`); the command line, config files and
:func:`nbcalib.calibrate` all map onto it, so its defaults are the only ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from nbcalib.odometry.config import (
    DEFAULT_FRAME_RATE,
    DEFAULT_MIN_DISTANCE,
    DEFAULT_VOXEL_SIZE,
    DynamicIntegrationConfig,
)

__all__ = ["MODES", "ORIGINS", "PreprocessConfig"]

#: Values of :attr:`PreprocessConfig.mode`.
MODES = ("auto", "static", "dynamic")

#: Words :attr:`PreprocessConfig.lidar_origin` takes besides three numbers.
ORIGINS = ("auto", "cloud")


@dataclass(frozen=True)
class PreprocessConfig:
    """How scans become a dense cloud and how the images are prepared.

    Attributes
    ----------
    mode : {"auto", "static", "dynamic"}
        ``static``: accumulate scans of a LiDAR at rest (non-repetitive scan LiDARs);
        ``dynamic``: continuous-time ICP for a moving spinning LiDAR
        (:mod:`nbcalib.odometry`); ``auto`` picks dynamic when there are several scans and the
        first covers more than 180 degrees of azimuth.
    voxel_size : float
        Output voxel of the dense cloud, metres (reference: 0.002).
    min_distance : float
        Points nearer than this to the sensor are dropped, metres (reference: 1.0).
    frame_rate : float
        Scans per second, for synthesising per-point times of files that carry none, Hz.
    equalize : bool
        Rank-equalise LiDAR intensities and histogram-equalise the camera image (paper III-C:
        NID works best with uniform intensity distributions).
    intensity_channel : str
        ``"auto"`` (``reflectivity`` over ``intensity``, as the reference) or a field name.
    points_topic, image_topic, camera_info_topic : str or None
        Bag topics; None picks the only topic of each kind.
    max_scans : int or None
        Use at most this many scans per pair.
    neighbors : int
        Scans per pair for pairs made per image (``--frames``, ``--images``, a bag's
        ``--every`` / ``--pair-count`` / ``--image-times``; :mod:`nbcalib.preprocess.recording`):
        the K scans around the image, its own scan among them. 1: the image's own scan alone
        (not deskewed: motion needs neighbours); the paper's single-shot protocol takes about
        10, accumulated as ``mode`` says. A recording with fewer scans gives each pair all of
        them (with a warning). A pair of all its scans (a bag without image selection, plain
        files with one image) refuses any other value than 1.
    image_scan_fraction : float
        When an image without a time was taken, as a fraction of its own scan's sweep (0 = the
        scan's first point, 1 = its last), for pairs made per image from frames or from
        ``--images`` without ``--image-times``; the dense cloud is expressed in the LiDAR frame at
        that time. 0.5: KITTI, and every camera triggered when a spinning LiDAR whose sweeps
        start behind it faces forward.
    lidar_origin : str
        Where the LiDAR sits in its clouds' frame (:mod:`nbcalib.preprocess.origin`):
        ``"auto"`` finds it from the rings of a spinning scan and moves it only from a frame
        clearly not centred on the sensor (a vehicle frame), ``"cloud"`` keeps the clouds'
        origin, ``"X,Y,Z"`` (metres) gives it. The LiDAR image and matching's views are
        rendered from there, and rotation-only RANSAC takes the camera to be there; the
        extrinsic stays in the clouds' frame.
    odometry : DynamicIntegrationConfig
        The continuous-time ICP of dynamic integration (:mod:`nbcalib.odometry.config`).
    """

    mode: str = "auto"
    voxel_size: float = DEFAULT_VOXEL_SIZE
    min_distance: float = DEFAULT_MIN_DISTANCE
    frame_rate: float = DEFAULT_FRAME_RATE
    equalize: bool = True
    intensity_channel: str = "auto"
    points_topic: str | None = None
    image_topic: str | None = None
    camera_info_topic: str | None = None
    max_scans: int | None = None
    neighbors: int = 1
    image_scan_fraction: float = 0.5
    lidar_origin: str = "auto"
    odometry: DynamicIntegrationConfig = field(default_factory=DynamicIntegrationConfig)

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if not (self.voxel_size > 0 and math.isfinite(self.voxel_size)):
            raise ValueError(f"voxel_size must be a positive number, got {self.voxel_size}")
        if not (self.min_distance >= 0 and math.isfinite(self.min_distance)):
            raise ValueError(f"min_distance must be >= 0, got {self.min_distance}")
        if not (self.frame_rate > 0 and math.isfinite(self.frame_rate)):
            raise ValueError(f"frame_rate must be > 0, got {self.frame_rate}")
        if self.max_scans is not None and self.max_scans < 1:
            raise ValueError(f"max_scans must be >= 1, got {self.max_scans}")
        if self.neighbors < 1:
            raise ValueError(f"neighbors must be >= 1, got {self.neighbors}")
        if not (0.0 <= self.image_scan_fraction <= 1.0):
            raise ValueError(
                f"image_scan_fraction must be in [0, 1], got {self.image_scan_fraction}"
            )
        self.given_origin()  # raises on a value that is neither a word nor three numbers
        if not self.intensity_channel:
            raise ValueError("intensity_channel must be 'auto' or a field name")

    def given_origin(self) -> tuple[float, float, float] | None:
        """:attr:`lidar_origin` as three numbers when given as such (else None)."""
        text = str(self.lidar_origin).strip().lower()
        if text in ORIGINS:
            return None
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            values = ()
        if len(values) != 3 or not all(math.isfinite(v) for v in values):
            raise ValueError(
                f"lidar_origin must be {' or '.join(ORIGINS)} or X,Y,Z in metres, "
                f"got {self.lidar_origin!r}"
            )
        return values
