"""Rig trajectories with ground-truth poses ``T_world_lidar(t)``.

A :class:`Trajectory` is a dense table of knots (1 ms apart by default) between which the pose is
interpolated as in ``docs/conventions.md`` section 3: the rotation by slerp (the geodesic
``R_k exp(s log(R_k^T R_k+1))``), the translation linearly. This interpolated curve *is* the
ground truth: the LiDAR simulator samples exactly it, so deskewing with
:meth:`Trajectory.poses` recovers the static scene to rounding.

Three motions, each starting at rest (the reference toolbox requires it: the image pairs with the
first scan, and the dense cloud is expressed in the LiDAR frame at the start of the first scan):

- ``"nod"``: the paper's collection procedure for spinning LiDARs: a slow up-down nodding
  (pitch about the LiDAR's y axis) with a small vertical bob and a little yaw sway, after a rest.
- ``"drive"``: accelerate smoothly from rest along the LiDAR's x axis, with a gentle turn and
  suspension pitch.
- ``"static"``: no motion (non-repetitive LiDARs are held still).

The world frame is the LiDAR frame at time 0, so ``T_world_lidar(0) = I``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nbcalib.transforms import make_T, so3_exp, so3_log

__all__ = ["MOTION_KINDS", "MotionConfig", "Trajectory", "make_trajectory"]

MOTION_KINDS = ("nod", "drive", "static")


@dataclass(frozen=True)
class MotionConfig:
    """How the rig moves.

    Parameters
    ----------
    kind : str
        ``"nod"``, ``"drive"`` or ``"static"``.
    rest : float
        Time at rest at the start, seconds (at least one scan, so the first scan is sharp).
    ramp : float
        Time over which the motion fades in after the rest, seconds (no jerk at the start).
    nod_amplitude_deg : float
        Peak pitch of the nodding, degrees.
    nod_period : float
        Period of one up-down nod, seconds.
    nod_bob : float
        Peak vertical translation while nodding, metres.
    sway_deg : float
        Peak yaw sway while nodding, degrees.
    speed : float
        Cruise speed of ``"drive"``, m/s.
    yaw_rate_deg : float
        Turn rate of ``"drive"`` at cruise speed, degrees per second.
    knot_interval : float
        Spacing of the trajectory's knots, seconds.
    seed : int
        Seed of the random phases (two seeds give two different nods).
    """

    kind: str = "nod"
    rest: float = 0.1
    ramp: float = 0.4
    nod_amplitude_deg: float = 12.0
    nod_period: float = 2.0
    nod_bob: float = 0.05
    sway_deg: float = 4.0
    speed: float = 4.0
    yaw_rate_deg: float = 3.0
    knot_interval: float = 1e-3
    seed: int = 0

    def __post_init__(self):
        if self.kind not in MOTION_KINDS:
            raise ValueError(f"motion kind must be one of {MOTION_KINDS}, got {self.kind!r}")
        if self.rest < 0 or self.ramp <= 0 or self.knot_interval <= 0 or self.nod_period <= 0:
            raise ValueError("rest must be >= 0; ramp, knot_interval and nod_period > 0")


class Trajectory:
    """Ground-truth poses ``T_world_lidar(t)`` interpolated between dense knots.

    Parameters
    ----------
    times : ndarray of shape (K,), float64
        Knot times, seconds, strictly increasing.
    rotations : ndarray of shape (K, 3, 3), float64
        ``R_world_lidar`` at the knots.
    translations : ndarray of shape (K, 3), float64
        ``t_world_lidar`` (the LiDAR origin in the world) at the knots, metres.

    Times outside ``[times[0], times[-1]]`` are clamped to the ends.
    """

    def __init__(self, times, rotations, translations):
        self.times = np.ascontiguousarray(times, dtype=np.float64)
        self.rotations = np.ascontiguousarray(rotations, dtype=np.float64)
        self.translations = np.ascontiguousarray(translations, dtype=np.float64)
        k = self.times.shape[0]
        if k < 2 or self.rotations.shape != (k, 3, 3) or self.translations.shape != (k, 3):
            raise ValueError("a trajectory needs K >= 2 knots: times (K,), R (K,3,3), t (K,3)")
        if not np.all(np.diff(self.times) > 0):
            raise ValueError("trajectory knot times must be strictly increasing")
        # rotation vector from each knot to the next: R_{k+1} = R_k exp(omega_k)
        relative = np.einsum("kji,kjl->kil", self.rotations[:-1], self.rotations[1:])
        self._omega = so3_log(relative)

    @property
    def duration(self) -> float:
        """Time span of the knots, seconds."""
        return float(self.times[-1] - self.times[0])

    def rotations_translations(self, t) -> tuple[np.ndarray, np.ndarray]:
        """``R_world_lidar`` (N, 3, 3) and ``t_world_lidar`` (N, 3) at times ``t`` (N,), seconds."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if not np.all(np.isfinite(t)):
            raise ValueError("trajectory times must be finite")
        t = np.clip(t, self.times[0], self.times[-1])
        k = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.times) - 2)
        s = (t - self.times[k]) / (self.times[k + 1] - self.times[k])
        R = self.rotations[k] @ so3_exp(s[:, None] * self._omega[k])
        p = self.translations[k] + s[:, None] * (self.translations[k + 1] - self.translations[k])
        return R, p

    def poses(self, t) -> np.ndarray:
        """``T_world_lidar`` at times ``t``: shape (N, 4, 4) for (N,) times, (4, 4) for a scalar."""
        R, p = self.rotations_translations(t)
        T = make_T(R, p)
        return T[0] if np.ndim(t) == 0 else T

    def pose(self, t: float) -> np.ndarray:
        """``T_world_lidar`` (4, 4) at one time, seconds."""
        return self.poses(float(t))


def _smoothstep(x):
    """0 below 0, 1 above 1, C2-smooth in between (zero velocity and acceleration at the ends)."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def _ramp_integral(t, ramp):
    """Integral of ``_smoothstep(t / ramp)`` from 0 to ``t`` (distance under a smooth start)."""
    x = np.clip(t / ramp, 0.0, 1.0)
    inside = ramp * (x**6 - 3.0 * x**5 + 2.5 * x**4)
    return np.where(t < ramp, inside, ramp * 0.5 + (t - ramp))


def make_trajectory(config: MotionConfig, duration: float) -> Trajectory:
    """Sample a motion into a :class:`Trajectory` covering ``[0, duration]`` seconds.

    Parameters
    ----------
    config : MotionConfig
        Kind and parameters of the motion.
    duration : float
        Length of the sequence, seconds.

    Returns
    -------
    Trajectory
        With ``T_world_lidar(0) = I`` and zero velocity during ``[0, config.rest]``.
    """
    if not duration > 0:
        raise ValueError(f"duration must be > 0, got {duration}")
    n = max(2, math.ceil(duration / config.knot_interval) + 1)
    t = np.linspace(0.0, n * config.knot_interval - config.knot_interval, n)
    rng = np.random.default_rng([config.seed, 0x30710])
    moving = np.maximum(t - config.rest, 0.0)
    envelope = _smoothstep(moving / config.ramp)
    roll = np.zeros(n)
    pitch = np.zeros(n)
    yaw = np.zeros(n)
    position = np.zeros((n, 3))
    if config.kind == "nod":
        phase = 2.0 * np.pi * moving / config.nod_period
        direction = rng.choice([-1.0, 1.0])
        sway_freq = rng.uniform(0.4, 0.7)
        # starts moving down (or up), oscillates about the start pose
        pitch = direction * np.radians(config.nod_amplitude_deg) * envelope * np.sin(phase)
        yaw = np.radians(config.sway_deg) * envelope * np.sin(sway_freq * phase)
        roll = np.radians(0.2 * config.sway_deg) * envelope * np.sin(1.3 * sway_freq * phase)
        position[:, 2] = config.nod_bob * envelope * np.sin(phase + rng.uniform(-0.5, 0.5))
    elif config.kind == "drive":
        yaw_rate = np.radians(config.yaw_rate_deg) * rng.choice([-1.0, 1.0])
        distance = config.speed * _ramp_integral(moving, config.ramp)
        yaw = yaw_rate / config.speed * distance  # heading follows the path's curvature
        pitch = np.radians(0.5) * envelope * np.sin(2.0 * np.pi * 0.7 * moving)
        # integrate the planar path with the trapezoid rule on the fine knot grid
        speed = config.speed * envelope
        heading_x, heading_y = np.cos(yaw) * speed, np.sin(yaw) * speed
        dt = np.diff(t)
        position[1:, 0] = np.cumsum(0.5 * (heading_x[1:] + heading_x[:-1]) * dt)
        position[1:, 1] = np.cumsum(0.5 * (heading_y[1:] + heading_y[:-1]) * dt)
        position[:, 2] = 0.01 * envelope * np.sin(2.0 * np.pi * 1.3 * moving)
    rotations = _rotation_zyx(yaw, pitch, roll)
    return Trajectory(t, rotations, position)


def _rotation_zyx(yaw, pitch, roll) -> np.ndarray:
    """``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` for arrays of angles, radians; shape (N, 3, 3)."""
    rz = so3_exp(np.stack([np.zeros_like(yaw), np.zeros_like(yaw), yaw], axis=1))
    ry = so3_exp(np.stack([np.zeros_like(pitch), pitch, np.zeros_like(pitch)], axis=1))
    rx = so3_exp(np.stack([roll, np.zeros_like(roll), np.zeros_like(roll)], axis=1))
    return rz @ ry @ rx
