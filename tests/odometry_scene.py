"""A small analytic scene for the odometry tests, scanned by a spinning LiDAR that moves.

A room with boxes, every surface a plane, and motions (constant velocity, at rest, at rest then
accelerating) for which the ground truth is known to rounding: at constant velocity the pose
interpolation of the method (slerp + lerp) is exact.
"""

from __future__ import annotations

import numpy as np

from nbcalib.transforms import make_T, so3_exp

ROOM = (np.array([-9.0, -7.0, -1.5]), np.array([11.0, 6.0, 3.5]))  # interior, LiDAR inside
BOXES = [  # solid boxes (lo, hi)
    (np.array([3.0, 2.0, -1.5]), np.array([4.5, 3.0, 0.5])),
    (np.array([-5.0, -5.5, -1.5]), np.array([-3.5, -3.0, 1.0])),
    (np.array([6.0, -4.0, -1.5]), np.array([7.0, -2.5, 2.0])),
    (np.array([-2.0, 3.5, 0.5]), np.array([0.5, 5.0, 1.5])),
]
SCAN_PERIOD = 0.1
#: constant velocity: world-frame linear velocity (m/s) and angular velocity (rad/s)
VELOCITY = np.array([1.5, 0.4, 0.05])
OMEGA = np.array([0.03, -0.05, 0.5])


def pattern(beams: int = 16, columns: int = 600):
    """Unit directions (LiDAR frame) and times of one sweep: clockwise from behind."""
    elevation = np.radians(np.linspace(-25.0, 20.0, beams))
    column = np.arange(columns)
    azimuth = np.pi - 2.0 * np.pi * column / columns
    az = np.repeat(azimuth, beams)
    el = np.tile(elevation, columns)
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    return d, np.repeat(column * SCAN_PERIOD / columns, beams)


def cast(origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Distance along each ray to the first surface of the scene."""
    lo, hi = ROOM
    with np.errstate(divide="ignore", invalid="ignore"):
        exit_t = np.where(directions > 0, (hi - origins) / directions, (lo - origins) / directions)
    best = np.nanmin(np.where(exit_t > 0, exit_t, np.inf), axis=1)
    for blo, bhi in BOXES:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = (blo - origins) / directions
            t2 = (bhi - origins) / directions
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        hit = (near <= far) & (near > 0)
        best = np.where(hit & (near < best), near, best)
    return best


def scene_distance(points_world: np.ndarray) -> np.ndarray:
    """Unsigned distance from each point to the nearest surface of the scene."""
    lo, hi = ROOM
    distance = np.min(np.abs(np.concatenate([points_world - lo, hi - points_world], axis=1)), 1)
    for blo, bhi in BOXES:
        c, h = 0.5 * (blo + bhi), 0.5 * (bhi - blo)
        q = np.abs(points_world - c) - h
        sdf = np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)
        distance = np.minimum(distance, np.abs(sdf))
    return distance


def constant_velocity(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """R_world_lidar (N, 3, 3) and t_world_lidar (N, 3) at times t (N,): constant velocity."""
    return so3_exp(t[:, None] * OMEGA), t[:, None] * VELOCITY


#: rest for one scan, then constant acceleration (m/s^2) and angular acceleration (rad/s^2)
ACCELERATION = np.array([3.0, 0.5, 0.0])
ANGULAR_ACCELERATION = np.array([0.0, 0.3, 4.0])


def rest_then_accelerate(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The collection procedure: still during the first scan, then speeding up from rest."""
    moving = np.maximum(t - SCAN_PERIOD, 0.0)[:, None]
    return so3_exp(0.5 * moving**2 * ANGULAR_ACCELERATION), 0.5 * moving**2 * ACCELERATION


def at_rest(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.broadcast_to(np.eye(3), (t.size, 3, 3)).copy(), np.zeros((t.size, 3))


def make_sequence(n_scans: int, *, noise: float = 0.003, seed: int = 0, motion=constant_velocity):
    """Scans (N, 4) x, y, z, intensity in the LiDAR frame at each point's time, their times and
    the true (T_world_begin, T_world_end) of each scan."""
    rng = np.random.default_rng(seed)
    d_lidar, times = pattern()
    scans, scan_times, truth = [], [], []
    for k in range(n_scans):
        t0 = k * SCAN_PERIOD
        R, origins = motion(t0 + times)
        d_world = np.einsum("nij,nj->ni", R, d_lidar)
        r = cast(origins, d_world) + noise * rng.standard_normal(times.size)
        hit_world = origins + r[:, None] * d_world
        intensity = 0.5 + 0.4 * np.sin(3.0 * hit_world[:, 0]) * np.cos(2.0 * hit_world[:, 2])
        scans.append(np.column_stack([r[:, None] * d_lidar, intensity]))
        scan_times.append(times.copy())
        ends = motion(np.array([t0, t0 + times[-1]]))
        truth.append(tuple(make_T(ends[0][j], ends[1][j]) for j in range(2)))
    return scans, scan_times, truth
