"""Do the given intrinsics agree with the data? The cost over the focal length, at a pose.

A focal length that is off by a fraction moves every pixel away from the principal point by
that fraction; a single view can absorb much of it in the camera's forward position, frames at
several depths cannot (issue 47). :func:`focal_scan` evaluates the job's summed cost
(:func:`~nbcalib.registration.costs.build_cost`, the cost fine registration minimises) at one
pose for the given camera with ``fx, fy`` scaled by each of ``scales``; the scale of the lowest
cost (a parabola through the lowest sample and its neighbours) says how far the data would move
the focal length, were the pose held.

This is the measuring instrument of issue 47's check (deliverable 4), not yet part of the
report: ``benchmarks/bench_intrinsics.py`` measures what it sees on the synthetic lab
(``nbcalib synth --given-focal-scale``) and on the real sets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from nbcalib.camera import CameraModel, offset_intrinsics

__all__ = ["FocalScan", "focal_scan", "scaled_focal"]

#: Focal scales of a scan: +-3 % in 0.5 % steps.
DEFAULT_SCALES = tuple(np.round(np.linspace(0.97, 1.03, 13), 6))


@dataclass(frozen=True)
class FocalScan:
    """The summed cost at one pose over focal scales of the given camera.

    Attributes
    ----------
    scales : ndarray
        ``fx, fy`` of the given camera times these.
    nid : ndarray
        The cost at each scale.
    best : float
        The scale of the lowest cost: the vertex of the parabola through the lowest sample and
        its two neighbours (the lowest sample itself at either end of the scan).
    """

    scales: np.ndarray
    nid: np.ndarray
    best: float

    @property
    def at_edge(self) -> bool:
        """The lowest cost lies at an end of the scan (the minimum may lie beyond it)."""
        k = int(np.argmin(self.nid))
        return k in (0, len(self.nid) - 1)

    def to_dict(self) -> dict:
        """JSON-ready: the scales, their costs, the best scale and whether it is at an end."""
        return {
            "scales": [float(s) for s in self.scales],
            "nid": [float(v) for v in self.nid],
            "best": float(self.best),
            "at_edge": self.at_edge,
        }


def scaled_focal(camera: CameraModel, scale: float) -> CameraModel:
    """``camera`` with ``fx, fy`` times ``scale`` (everything else as it is)."""
    return offset_intrinsics(camera, focal_scale=scale)


def _vertex(x: np.ndarray, y: np.ndarray) -> float:
    """The vertex of the parabola through the lowest sample and its two neighbours.

    The lowest sample itself at either end, or where the three are not convex.
    """
    k = int(np.argmin(y))
    if k == 0 or k == len(y) - 1:
        return float(x[k])
    a, b, _ = np.polyfit(x[k - 1 : k + 2], y[k - 1 : k + 2], 2)
    return float(-b / (2 * a)) if a > 0 else float(x[k])


def focal_scan(
    pairs: Sequence,
    T_camera_lidar,
    config,
    scales: Sequence[float] = DEFAULT_SCALES,
) -> FocalScan:
    """The summed cost of ``pairs`` at ``T_camera_lidar`` over focal scales of their camera.

    Parameters
    ----------
    pairs : sequence of RegistrationPair
        The job's pairs (their ``camera`` is the given one).
    T_camera_lidar : ndarray of shape (4, 4)
        The pose held fixed (the result, or a reference).
    config : RefineConfig
        The cost's settings (:func:`~nbcalib.registration.costs.build_cost`).
    scales : sequence of float
        Focal scales to evaluate, increasing (default :data:`DEFAULT_SCALES`).

    Returns
    -------
    FocalScan
    """
    from nbcalib.registration.costs import build_cost

    scales = np.asarray(scales, dtype=np.float64)
    if scales.ndim != 1 or len(scales) < 3 or np.any(np.diff(scales) <= 0):
        raise ValueError("scales must be at least three increasing numbers")
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    values = []
    for scale in scales:
        scaled = [replace(pair, camera=scaled_focal(pair.camera, scale)) for pair in pairs]
        cost, _ = build_cost(scaled, T, config)
        values.append(cost.value(T))
    nid = np.asarray(values)
    return FocalScan(scales, nid, _vertex(scales, nid))
