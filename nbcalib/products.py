"""What each stage of the pipeline hands to the next (:class:`nbcalib.pipeline.Calibrator`).

=======================  ===============================================  =====================
stage (paper section)    product                                          made by
=======================  ===============================================  =====================
preprocess (III-C)       :class:`PairData` per pair: dense cloud, image   :mod:`nbcalib.preprocess`
render (III-D)           :class:`VirtualCamera` and a                     :mod:`nbcalib.preprocess.
                         :class:`~nbcalib.preprocess.lidar_image.         lidar_image`
                         LidarImage` per pair (intensity, index map)
match (III-D)            :class:`~nbcalib.matching.find.PairMatches` per  :mod:`nbcalib.matching`
                         pair: 2D-3D correspondences
initial guess (III-D)    :class:`~nbcalib.initial_guess.estimate.         :mod:`nbcalib.
                         InitialGuess` (or a given start pose)            initial_guess`
refine (III-E)           :class:`~nbcalib.registration.refine.            :mod:`nbcalib.
                         RefineResult`                                    registration`
assess (nbcalib)         :class:`~nbcalib.report.quality.Quality`         :mod:`nbcalib.report`
=======================  ===============================================  =====================

:class:`CalibrationResult` gathers them at the end of a job; :class:`Start` is a pose the user
gives (a start for fine registration, or a prior for matching).

Every product is exactly what the work directory stores (:mod:`nbcalib.workdir`), so a job run
in memory and a job run stage by stage through files compute the same numbers: clouds and
intensities are float32 values (the PLY's precision), images uint8, and poses pass between
stages as ``calib.json``'s seven numbers ``[x, y, z, qx, qy, qz, qw]`` (:class:`Start`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from nbcalib.clouds import Cloud

if TYPE_CHECKING:  # the camera module loads the numba kernels
    from nbcalib.camera import CameraModel

__all__ = [
    "CalibrationResult",
    "PairData",
    "Start",
    "VirtualCamera",
    "as_stored_values",
    "check_uncertainty",
]


@dataclass(frozen=True, eq=False)
class VirtualCamera:
    """The camera that renders every pair's LiDAR image (paper III-D, Fig. 4).

    Attributes
    ----------
    camera : CameraModel
        Pinhole for a LiDAR field of view under 150 degrees, else equirectangular.
    T_vcam_lidar : ndarray of shape (4, 4), float64
        ``p_vcam = T_vcam_lidar @ p_lidar``: a rotation, placed at the LiDAR's origin in the
        clouds' frame (:mod:`nbcalib.preprocess.origin`; the clouds' own origin unless they are
        in a frame not centred on the sensor).
    fov_deg : float or None
        The LiDAR field of view it was chosen for, degrees (None when loaded from a work
        directory that does not record it).
    """

    camera: CameraModel
    T_vcam_lidar: np.ndarray
    fov_deg: float | None = None

    @property
    def origin(self) -> np.ndarray:
        """The LiDAR's position in the clouds' frame, where the virtual camera sits, metres."""
        T = np.asarray(self.T_vcam_lidar, dtype=np.float64)
        return -T[:3, :3].T @ T[:3, 3]


@dataclass(frozen=True, eq=False, init=False)
class PairData:
    """One LiDAR-camera pair after preprocessing (and rendering).

    Attributes
    ----------
    name : str
        Data name (a bag's name, or ``000000``, ``000001``... for plain files).
    image : ndarray of shape (H, W), uint8
        The camera image as used: grey, histogram-equalised unless switched off.
    cloud : Cloud
        The dense cloud and its intensities, held or read from the work directory when
        needed (:mod:`nbcalib.clouds`); :attr:`points_lidar` and :attr:`intensities` are its
        arrays.
    lidar_image : LidarImage or None
        The virtual camera's rendering of the cloud: intensity image and index map (rows of
        ``points_lidar``, -1 empty); None before the render step.
    summary : dict
        What preprocessing did (mode, scans, points), for records.

    ``PairData(name, image, points_lidar, intensities, lidar_image, summary)`` holds the
    arrays; ``PairData(name, image, cloud=cloud, ...)`` takes a cloud.
    """

    name: str
    image: np.ndarray
    cloud: Cloud
    lidar_image: object = None
    summary: dict | None = None

    def __init__(
        self,
        name: str,
        image: np.ndarray,
        points_lidar=None,
        intensities=None,
        lidar_image=None,
        summary: dict | None = None,
        *,
        cloud: Cloud | None = None,
    ):
        cloud = Cloud.given(cloud, points_lidar, intensities)
        for key, value in (
            ("name", name),
            ("image", image),
            ("cloud", cloud),
            ("lidar_image", lidar_image),
            ("summary", summary),
        ):
            object.__setattr__(self, key, value)

    def __len__(self) -> int:
        return len(self.cloud)

    @property
    def points_lidar(self) -> np.ndarray:
        """The dense cloud (N, 3), LiDAR frame, metres, float64 (float32 values: the PLY's)."""
        return self.cloud.points

    @property
    def intensities(self) -> np.ndarray:
        """Equalised intensities (N,) in [0, 1) (float32 values), float64."""
        return self.cloud.intensities

    @property
    def lidar_index(self) -> np.ndarray:
        """The index map of :attr:`lidar_image` (row of ``points_lidar`` per pixel, -1 empty)."""
        return self.lidar_image.index


def as_stored_values(T_camera_lidar) -> list[float]:
    """``T_camera_lidar`` as ``calib.json`` stores it: ``T_lidar_camera`` [x, y, z, qx, qy, qz, qw].

    Parameters
    ----------
    T_camera_lidar : array_like of shape (4, 4)
        ``p_camera = T_camera_lidar @ p_lidar``.
    """
    from nbcalib.io.calib_json import values_from_T_camera_lidar

    return [float(v) for v in values_from_T_camera_lidar(np.asarray(T_camera_lidar, float))]


@dataclass(frozen=True, eq=False)
class Start:
    """A pose the user gives: the start of fine registration, or a prior for matching.

    A start is its seven stored numbers, so that a start written to ``calib.json`` and read back
    (by a stage run on its own) is the same pose to the bit.

    Attributes
    ----------
    values : tuple of 7 float
        ``T_lidar_camera`` as ``[x, y, z, qx, qy, qz, qw]`` (``calib.json``'s layout).
    source : str
        Where it came from, for records and messages (``--init``, ``T_init``,
        ``init_T_lidar_camera_auto``...).
    uncertainty : tuple of 2 float or None
        How far the start may be from the truth, as a bound at the report's confidence: metres
        (camera centre) and degrees (``--init-uncertainty``); None when not stated (the
        verdict then takes the trust region of fine registration as the start's uncertainty:
        :mod:`nbcalib.report.quality`).
    """

    values: tuple
    source: str
    uncertainty: tuple | None = None

    def __post_init__(self):
        if self.uncertainty is not None:
            object.__setattr__(
                self, "uncertainty", check_uncertainty(self.uncertainty, self.source)
            )

    @classmethod
    def from_matrix(cls, T_camera_lidar, source: str, uncertainty=None) -> Start:
        """A start from a 4 x 4 ``T_camera_lidar`` (checked)."""
        from nbcalib.transforms import validate_T

        T = validate_T(np.asarray(T_camera_lidar, dtype=np.float64), source)
        return cls(tuple(as_stored_values(T)), source, uncertainty)

    @classmethod
    def from_values(cls, values, source: str, uncertainty=None) -> Start:
        """A start from ``T_lidar_camera`` as ``[x, y, z, qx, qy, qz, qw]`` (checked)."""
        from nbcalib.io.calib_json import T_camera_lidar_from_values

        T_camera_lidar_from_values(list(values), what=source)
        return cls(tuple(float(v) for v in values), source, uncertainty)

    @property
    def T_camera_lidar(self) -> np.ndarray:
        """The pose, ``p_camera = T_camera_lidar @ p_lidar``, (4, 4) float64."""
        from nbcalib.io.calib_json import T_camera_lidar_from_values

        return T_camera_lidar_from_values(list(self.values), what=self.source)


def check_uncertainty(value, what: str = "uncertainty") -> tuple[float, float]:
    """``(metres, degrees)``, two finite numbers >= 0, or a ValueError naming ``what``."""
    try:
        metres, degrees = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(
            f"the uncertainty of {what} must be two numbers, metres and degrees, got {value!r}"
        ) from None
    if not (np.isfinite(metres) and np.isfinite(degrees) and metres >= 0 and degrees >= 0):
        raise ValueError(
            f"the uncertainty of {what} must be two finite numbers >= 0 (metres, degrees), "
            f"got {metres}, {degrees}"
        )
    return metres, degrees


@dataclass
class CalibrationResult:
    """The extrinsic, how it was found, and how far to trust it.

    Attributes
    ----------
    T_camera_lidar : ndarray of shape (4, 4), float64
        ``p_camera = T_camera_lidar @ p_lidar``: the result of fine registration.
    T_init : ndarray of shape (4, 4), float64
        Where fine registration started (``T_camera_lidar`` form).
    init_source : str
        Where that start came from: ``init_T_lidar_camera_auto`` (the automatic guess),
        ``init_T_lidar_camera`` (manual picks), or the given pose (``T_init``, ``--init``).
    initial_guess : InitialGuess or None
        The guess this run estimated (None when it started from a given pose).
    pairs : list of PairData
        The pairs' products (dense cloud, image, LiDAR image and index map).
    matches : list of PairMatches
        Matching's correspondences per pair (empty when matching did not run).
    refinement : RefineResult
        Fine registration: ``history`` holds each outer iteration.
    quality : Quality or None
        Uncertainty and verdict (None when the assessment did not run).
    camera : CameraModel
        The camera the result goes with: the one given, or the one fine registration refined
        with it (``refine.intrinsics``; ``refinement.intrinsics`` tells how and whether).
    virtual_camera : VirtualCamera or None
        The camera of the LiDAR images.
    workdir : pathlib.Path or None
        The work directory, if the job kept one.
    seconds : dict of str to float
        Wall time of each stage that ran.
    """

    T_camera_lidar: np.ndarray
    T_init: np.ndarray
    init_source: str
    initial_guess: object
    pairs: list
    refinement: object
    camera: object
    quality: object = None
    matches: list = field(default_factory=list)
    virtual_camera: object = None
    workdir: Path | None = None
    seconds: dict = field(default_factory=dict)
    values: tuple = ()

    def __post_init__(self):
        if not self.values:
            self.values = tuple(as_stored_values(self.T_camera_lidar))

    @property
    def T_lidar_camera(self) -> np.ndarray:
        """``p_lidar = T_lidar_camera @ p_camera`` (the ``calib.json`` direction), (4, 4)."""
        from nbcalib.transforms import invert_T

        return invert_T(self.T_camera_lidar)

    @property
    def xyz_quat(self) -> list[float]:
        """``T_lidar_camera`` as ``[x, y, z, qx, qy, qz, qw]``, as ``calib.json`` holds it."""
        return list(self.values)

    @property
    def nid_history(self) -> list[float]:
        """NID at the start, then after each outer iteration of fine registration."""
        history = self.refinement.history
        return [history[0].nid_start, *(step.nid for step in history)] if history else []

    def __repr__(self) -> str:
        values = ", ".join(f"{v:.4f}" for v in self.xyz_quat)
        verdict = f", verdict {self.quality.verdict}" if self.quality is not None else ""
        return (
            f"CalibrationResult(T_lidar_camera=[{values}] (x y z qx qy qz qw), "
            f"{len(self.pairs)} pair(s), start: {self.init_source}{verdict})"
        )
