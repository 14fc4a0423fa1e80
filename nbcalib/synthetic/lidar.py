"""LiDAR models: spinning multi-beam and non-repetitive rosette, with noise and motion distortion.

Both kinds produce, per scan, the beam directions in the sensor frame, the firing time of each
point relative to the scan start and its ring (beam) index; :func:`simulate_scan` then casts each
beam from the pose the rig has *at that point's time* and reports the point in the LiDAR frame of
that time, which is how a real sensor's sweep gets distorted by motion.

- :class:`SpinningLidarConfig`: ``beams`` lasers at evenly spaced elevations over the vertical
  field of view, fired together ``columns`` times per revolution while the head turns at
  ``rotation_hz`` (clockwise seen from above, starting behind the sensor, like Ouster and
  Velodyne). Points are ordered by column, then ring (ring 0 = lowest beam), so the per-point
  times are non-decreasing.
- :class:`RosetteLidarConfig`: a Livox-Avia-like sensor: each of ``beams`` lasers is steered by
  two counter-rotating prisms whose frequencies have an irrational ratio, tracing a rosette that
  never repeats and fills an ellipse of ``fov_deg`` (70.4 x 77.2 degrees) over time.

Returns are lost beyond ``max_range`` or below ``min_range``, at random (``dropout``), on
glass-like materials, at grazing incidence and when the returned signal is too weak. Intensity is
``255 * reflectivity * cos(incidence)**incidence_exponent * min(1, reference_range /
range)**range_exponent``, with multiplicative noise, clipped to [0, 255]; retro-reflectors
saturate at 255 at any incidence.

``nbcalib synth --without lidar-noise`` and ``--without lidar-falloff`` are configurations of
these fields (:func:`nbcalib.synthetic.effects.lidar_without`); the texture switches come with
the scene (``Scene.without``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from nbcalib.kernels import synthetic_lidar as _sl
from nbcalib.synthetic.motion import Trajectory
from nbcalib.synthetic.scene import Scene
from nbcalib.synthetic.texture import texture_bits

__all__ = [
    "LIDAR_PRESETS",
    "LidarConfig",
    "LidarScan",
    "RosetteLidarConfig",
    "SpinningLidarConfig",
    "lidar_preset",
    "simulate_scan",
]


@dataclass(frozen=True)
class LidarConfig:
    """Parameters shared by every LiDAR model (noise, range, intensity).

    Parameters
    ----------
    name : str
        Preset name, for files and ground truth.
    scan_period : float
        Duration of one scan (message), seconds.
    max_range, min_range : float
        Returns outside ``[min_range, max_range]`` are lost, metres.
    range_noise : float
        Standard deviation of the Gaussian range noise, metres.
    intensity_noise : float
        Relative standard deviation of the multiplicative intensity noise.
    dropout : float
        Probability that any return is lost at random.
    incidence_exponent : float
        Intensity falls as ``cos(incidence) ** incidence_exponent``.
    range_exponent : float
        Intensity falls as ``(reference_range / range) ** range_exponent`` beyond
        ``reference_range`` (0: fully range-compensated, 2: raw inverse-square).
    reference_range : float
        Range below which intensity does not grow any more, metres.
    min_signal : float
        Returns whose relative signal (reflectivity x incidence x range terms) is below this
        are lost.
    beam_divergence : float
        Full angle of the laser spot, radians; texture finer than the spot is averaged.
    """

    name: str = "lidar"
    scan_period: float = 0.1
    max_range: float = 120.0
    min_range: float = 0.3
    range_noise: float = 0.01
    intensity_noise: float = 0.03
    dropout: float = 0.01
    incidence_exponent: float = 1.0
    range_exponent: float = 0.5
    reference_range: float = 5.0
    min_signal: float = 0.004
    beam_divergence: float = 0.003

    def __post_init__(self):
        if not (self.scan_period > 0 and 0 <= self.min_range < self.max_range):
            raise ValueError("need scan_period > 0 and 0 <= min_range < max_range")
        if not (0 <= self.dropout < 1 and self.range_noise >= 0 and self.intensity_noise >= 0):
            raise ValueError("need 0 <= dropout < 1 and non-negative noise levels")

    @property
    def kind(self) -> str:
        """``"spinning"`` or ``"rosette"``."""
        raise NotImplementedError

    def pattern(self, t_start: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beams of the scan starting at ``t_start`` seconds (sequence time).

        Returns
        -------
        directions : ndarray of shape (N, 3), float64
            Unit beam directions in the LiDAR frame (x forward, y left, z up).
        times : ndarray of shape (N,), float64
            Firing time of each beam relative to the scan start, seconds, non-decreasing.
        rings : ndarray of shape (N,), uint16
            Beam (laser) index of each point.
        """
        raise NotImplementedError


@dataclass(frozen=True)
class SpinningLidarConfig(LidarConfig):
    """A spinning multi-beam LiDAR (Velodyne, Ouster, Hesai kind).

    Parameters
    ----------
    beams : int
        Number of lasers (rings).
    vertical_fov_deg : tuple of 2 floats
        Elevation of the lowest and of the highest beam, degrees.
    columns : int
        Firings per revolution (azimuth resolution ``360 / columns`` degrees).
    start_azimuth_deg : float
        Azimuth of the first column, degrees (180: behind the sensor).
    clockwise : bool
        Head turns clockwise seen from above (azimuth decreasing), as Velodyne and Ouster.

    The rotation rate is ``1 / scan_period`` (one revolution per scan).
    """

    name: str = "spinning64"
    beams: int = 64
    vertical_fov_deg: tuple[float, float] = (-22.5, 22.5)
    columns: int = 1024
    start_azimuth_deg: float = 180.0
    clockwise: bool = True

    def __post_init__(self):
        super().__post_init__()
        if self.beams < 1 or self.columns < 1:
            raise ValueError("beams and columns must be positive")
        if not self.vertical_fov_deg[0] <= self.vertical_fov_deg[1]:
            raise ValueError("vertical_fov_deg must be (lowest, highest)")

    @property
    def kind(self) -> str:
        """``"spinning"``."""
        return "spinning"

    @property
    def rotation_hz(self) -> float:
        """Revolutions per second."""
        return 1.0 / self.scan_period

    @property
    def azimuth_resolution_deg(self) -> float:
        """Angle between two columns, degrees."""
        return 360.0 / self.columns

    @property
    def points_per_scan(self) -> int:
        """Beams fired per scan (before dropouts)."""
        return self.beams * self.columns

    def pattern(self, t_start: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beams of one revolution (the same for every scan); see :meth:`LidarConfig.pattern`."""
        return _spinning_pattern(self)


@functools.lru_cache(maxsize=8)
def _spinning_pattern(lidar: SpinningLidarConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The beams of one revolution, computed once per configuration (read-only arrays)."""
    lo, hi = np.radians(lidar.vertical_fov_deg)
    elevation = np.linspace(lo, hi, lidar.beams) if lidar.beams > 1 else np.array([lo])
    column = np.arange(lidar.columns)
    sign = -1.0 if lidar.clockwise else 1.0
    azimuth = np.radians(lidar.start_azimuth_deg) + sign * 2.0 * np.pi * column / lidar.columns
    az = np.repeat(azimuth, lidar.beams)
    el = np.tile(elevation, lidar.columns)
    directions = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    times = np.repeat(column * (lidar.scan_period / lidar.columns), lidar.beams)
    rings = np.tile(np.arange(lidar.beams, dtype=np.uint16), lidar.columns)
    for array in (directions, times, rings):
        array.setflags(write=False)
    return directions, times, rings


@dataclass(frozen=True)
class RosetteLidarConfig(LidarConfig):
    """A non-repetitive rosette-scanning LiDAR (Livox Avia kind).

    Parameters
    ----------
    fov_deg : tuple of 2 floats
        Full horizontal and vertical field of view, degrees (an ellipse).
    points_per_second : int
        Returns per second, all beams together.
    beams : int
        Lasers; each traces the rosette with its own phase and a small angular offset.
    prism_hz : tuple of 2 floats
        Rotation frequencies of the two prisms, Hz, opposite signs, irrational ratio.
    beam_spacing_deg : float
        Angular spacing of the lasers across the field of view, degrees.
    """

    name: str = "livox"
    scan_period: float = 0.1
    max_range: float = 190.0
    min_range: float = 1.0
    range_noise: float = 0.02
    fov_deg: tuple[float, float] = (70.4, 77.2)
    points_per_second: int = 240_000
    beams: int = 6
    prism_hz: tuple[float, float] = (121.57, -77.73 * math.sqrt(1.0007))
    beam_spacing_deg: float = 0.35

    def __post_init__(self):
        super().__post_init__()
        if self.beams < 1 or self.points_per_second < self.beams:
            raise ValueError("need beams >= 1 and points_per_second >= beams")
        if self.prism_hz[0] * self.prism_hz[1] >= 0:
            raise ValueError("prism_hz must have opposite signs (counter-rotating prisms)")

    @property
    def kind(self) -> str:
        """``"rosette"``."""
        return "rosette"

    @property
    def points_per_scan(self) -> int:
        """Beams fired per scan (before dropouts and field-of-view clipping)."""
        return round(self.points_per_second * self.scan_period)

    def angles(self, t: np.ndarray, beam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Azimuth and elevation, radians, of the given beams at absolute times ``t``, seconds.

        Two counter-rotating prisms of equal deflection give the deflection
        ``(exp(i w1 t) + exp(i (w2 t + phase))) / 2`` (a rosette through the centre); it is
        scaled onto the field-of-view ellipse, and each beam is offset a little vertically.
        """
        w1, w2 = 2.0 * np.pi * np.asarray(self.prism_hz)
        phase = 2.0 * np.pi * beam / self.beams
        dx = 0.5 * (np.cos(w1 * t) + np.cos(w2 * t + phase))
        dy = 0.5 * (np.sin(w1 * t) + np.sin(w2 * t + phase))
        offset = (beam - 0.5 * (self.beams - 1)) * math.radians(self.beam_spacing_deg)
        half_h, half_v = np.radians(self.fov_deg) / 2.0
        return dx * half_h, dy * half_v + offset

    def pattern(self, t_start: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Beams fired during ``[t_start, t_start + scan_period)``; see :meth:`LidarConfig.pattern`.

        Beams fire in turn, one point every ``1 / points_per_second`` seconds; points that the
        beam offsets push outside the field-of-view ellipse are not returned.
        """
        n = self.points_per_scan
        # index of the first point of this scan in the never-ending firing sequence
        first = round(t_start * self.points_per_second)
        index = first + np.arange(n)
        times = (index - first) / self.points_per_second
        beam = index % self.beams
        azimuth, elevation = self.angles(index / self.points_per_second, beam)
        half_h, half_v = np.radians(self.fov_deg) / 2.0
        inside = (azimuth / half_h) ** 2 + (elevation / half_v) ** 2 <= 1.0
        azimuth, elevation = azimuth[inside], elevation[inside]
        directions = np.stack(
            [
                np.cos(elevation) * np.cos(azimuth),
                np.cos(elevation) * np.sin(azimuth),
                np.sin(elevation),
            ],
            axis=1,
        )
        return directions, times[inside], beam[inside].astype(np.uint16)


#: Presets of ``nbcalib synth --lidar``: Velodyne VLP-16, Velodyne HDL-32E, Ouster OS1-64 and
#: OS1-128, Livox Avia (field of view, resolution, rate, range and noise of the data sheets).
LIDAR_PRESETS: dict[str, LidarConfig] = {
    "spinning16": SpinningLidarConfig(
        name="spinning16",
        beams=16,
        vertical_fov_deg=(-15.0, 15.0),
        columns=1800,
        max_range=100.0,
        range_noise=0.02,
    ),
    "spinning32": SpinningLidarConfig(
        name="spinning32",
        beams=32,
        vertical_fov_deg=(-30.67, 10.67),
        columns=2048,
        max_range=100.0,
        range_noise=0.02,
    ),
    "spinning64": SpinningLidarConfig(name="spinning64"),
    "spinning128": SpinningLidarConfig(name="spinning128", beams=128),
    "livox": RosetteLidarConfig(),
}


def lidar_preset(name: str, **overrides) -> LidarConfig:
    """A copy of a preset of :data:`LIDAR_PRESETS` with some fields replaced."""
    if name not in LIDAR_PRESETS:
        raise ValueError(f"unknown LiDAR {name!r}; expected one of {sorted(LIDAR_PRESETS)}")
    preset = LIDAR_PRESETS[name]
    return type(preset)(**{**preset.__dict__, **overrides})


@dataclass(frozen=True, eq=False)
class LidarScan:
    """One scan as the sensor reports it, plus its ground truth.

    Attributes
    ----------
    points : ndarray of shape (N, 3), float64
        Each point in the LiDAR frame at its own firing time (motion-distorted), metres.
    intensities : ndarray of shape (N,), float64
        Intensity in [0, 255].
    times : ndarray of shape (N,), float64
        Firing time relative to ``stamp``, seconds, non-decreasing.
    rings : ndarray of shape (N,), uint16
        Beam index.
    stamp : float
        Scan start, seconds of sequence time (0 = the first scan's start = the image).
    points_undistorted : ndarray of shape (N, 3), float64
        The same points in the LiDAR frame at the scan start (ground-truth deskewing), metres.
    prim : ndarray of shape (N,), int64
        Index of the scene primitive each point lies on.
    """

    points: np.ndarray
    intensities: np.ndarray
    times: np.ndarray
    rings: np.ndarray
    stamp: float
    points_undistorted: np.ndarray
    prim: np.ndarray = field(repr=False)

    def __len__(self) -> int:
        return self.points.shape[0]


def simulate_scan(
    scene: Scene,
    lidar: LidarConfig,
    trajectory: Trajectory,
    t_start: float,
    rng: np.random.Generator,
    *,
    parallel: bool = False,
) -> LidarScan:
    """Simulate one scan of ``lidar`` moving along ``trajectory`` through ``scene``.

    Parameters
    ----------
    scene : Scene
        What the beams hit (world frame), with its modality gap and texture switches.
    lidar : LidarConfig
        The sensor (pattern, noise, intensity model).
    trajectory : Trajectory
        Ground-truth ``T_world_lidar(t)``.
    t_start : float
        Scan start, seconds of sequence time.
    rng : numpy.random.Generator
        Source of the noise and dropouts (drawn in a fixed order: same seed, same scan).
    parallel : bool
        Use the parallel ray-casting kernel (same result).

    Returns
    -------
    LidarScan
    """
    directions_lidar, times, rings = lidar.pattern(t_start)
    n = times.shape[0]
    if n == 0:
        empty = np.zeros((0, 3))
        return LidarScan(
            empty,
            np.zeros(0),
            np.zeros(0),
            rings,
            float(t_start),
            empty,
            np.zeros(0, dtype=np.int64),
        )
    # noise is drawn before anything else, in a fixed order and amount, for reproducibility
    range_noise = rng.standard_normal(n) * lidar.range_noise
    intensity_noise = rng.standard_normal(n) * lidar.intensity_noise
    lost = rng.random(n)

    # pose of the rig at each distinct firing time (a spinning LiDAR fires a column at once);
    # times are non-decreasing, so the distinct ones are where they change
    change = np.ones(n, dtype=bool)
    change[1:] = times[1:] != times[:-1]
    unique_times = times[change]
    which = np.cumsum(change) - 1
    R_world_lidar, t_world_lidar = trajectory.rotations_translations(t_start + unique_times)
    params = np.array(
        [
            lidar.min_range,
            lidar.max_range,
            lidar.max_range + 5.0 * lidar.range_noise,  # noise may bring a farther hit inside
            lidar.dropout,
            lidar.incidence_exponent,
            lidar.range_exponent,
            lidar.reference_range,
            lidar.min_signal,
            lidar.beam_divergence,
        ]
    )
    keep = np.empty(n, dtype=np.bool_)
    ranges = np.empty(n)
    intensity = np.empty(n)
    points_start = np.empty((n, 3))
    prim = np.empty(n, dtype=np.int64)
    R0, p0 = trajectory.rotations_translations(t_start)
    kernel = _sl._returns_parallel if parallel else _sl._returns
    kernel(
        scene.prims,
        scene.bvh_bounds,
        scene.bvh_nodes,
        scene.bvh_order,
        scene.materials,
        float(scene.modality_gap),
        texture_bits(scene.without),
        np.ascontiguousarray(R_world_lidar),
        np.ascontiguousarray(t_world_lidar),
        np.ascontiguousarray(which.ravel(), dtype=np.int64),
        np.ascontiguousarray(directions_lidar, dtype=np.float64),
        range_noise,
        intensity_noise,
        lost,
        params,
        np.ascontiguousarray(R0[0]),
        np.ascontiguousarray(p0[0]),
        keep,
        ranges,
        intensity,
        points_start,
        prim,
    )
    points = ranges[keep, None] * directions_lidar[keep]
    points_undistorted = points_start[keep]
    return LidarScan(
        points=points,
        intensities=intensity[keep],
        times=times[keep],
        rings=rings[keep],
        stamp=float(t_start),
        points_undistorted=points_undistorted,
        prim=prim[keep],
    )
