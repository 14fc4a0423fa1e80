"""Do the given intrinsics agree with the data? The cost over the focal length, at a pose.

A focal length that is off by a fraction moves every pixel away from the principal point by
that fraction; a single view can absorb much of it in the camera's forward position, frames at
several depths cannot (issue 47). :func:`focal_scan` evaluates the job's summed cost
(:func:`~nbcalib.registration.costs.build_cost`, the cost fine registration minimises) at one
pose for the given camera with ``fx, fy`` scaled by each of ``scales``; the scale of the lowest
cost (a parabola through the lowest sample and its neighbours) says how far the data would move
the focal length, were the pose held.

At the result of fine registration the scan sees little: the pose has absorbed what it could
(docs/BENCHMARKS.md 14). So the report's check, :func:`check_intrinsics`, lets the pose move:
it takes the Newton step of the joint cost in the pose and the focal scale from the result
(their gradient and Hessian over every pair, :func:`nbcalib.registration.intrinsics.
identifiability`), the profile's minimum to second order, and looks along it for the cost's
lowest value (:func:`_along`), with the 95 % bound from leaving each pair out. A focal length
that the data would move by more than ``assess.intrinsics_tolerance`` and by more than its bound
does not agree with the data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from nbcalib.camera import CameraModel, offset_intrinsics

__all__ = ["FocalScan", "IntrinsicsCheck", "check_intrinsics", "focal_scan", "scaled_focal"]

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


@dataclass(frozen=True)
class IntrinsicsCheck:
    """Do the given intrinsics agree with the data at the result? (:func:`check_intrinsics`).

    Attributes
    ----------
    checked : bool
        False for a job the check cannot judge (fewer than three pairs): :attr:`note` says so.
    agrees : bool
        The focal length the data point to is within the tolerance, or within its own bound.
    focal_scale : float
        The focal length the joint cost's minimum has, over the given one (NaN unchecked).
    focal_bound_percent : float
        Its 95 % half-width, per cent.
    correlation : float
        Of focal length and forward translation at the result.
    note : str
        One line for the report: what was found and, when it disagrees, what to do.
    """

    checked: bool
    agrees: bool
    focal_scale: float
    focal_bound_percent: float
    correlation: float
    note: str

    def to_dict(self) -> dict:
        """JSON-ready (``nbcalib.quality.intrinsics_check`` of ``calib.json``)."""
        import math

        def finite(x):
            return float(x) if math.isfinite(x) else None

        return {
            "checked": self.checked,
            "agrees": self.agrees,
            "focal_scale": finite(self.focal_scale),
            "focal_bound_percent": finite(self.focal_bound_percent),
            "correlation_focal_forward": finite(self.correlation),
            "note": self.note,
        }


#: Fractions of the Newton step at which :func:`_along` evaluates the cost.
STEP_FRACTIONS = (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5)


def _along(pairs, T: np.ndarray, newton: np.ndarray, config) -> tuple[float, np.ndarray]:
    """Where the joint cost is lowest along its Newton step from ``T``: (fraction, step).

    One Newton step is the minimum of the cost's quadratic model, which over a focal error of
    a few per cent overshoots (a 2 % error measured as 2.8 %, tests/test_refine_intrinsics.py):
    the cost's own values at :data:`STEP_FRACTIONS` of the step, and the vertex of the parabola
    through the lowest and its neighbours, say how far along it the minimum lies.
    """
    from nbcalib.registration.costs import build_cost
    from nbcalib.transforms import se3_exp

    step = np.asarray(newton, dtype=np.float64)
    step = step * min(1.0, 0.1 / max(abs(float(step[6])), 1e-12))  # at most 10 % of focal
    cost, _ = build_cost(pairs, T, config)
    fractions = np.asarray(STEP_FRACTIONS)
    values = [cost.value(se3_exp(f * step[:6]) @ T, intrinsics=f * step[6:]) for f in fractions]
    return float(_vertex(fractions, np.asarray(values))), step


def check_intrinsics(pairs: Sequence, T_camera_lidar, config, tolerance: float) -> IntrinsicsCheck:
    """Whether the given focal length agrees with the data at ``T_camera_lidar`` (module doc).

    Parameters
    ----------
    pairs : sequence of RegistrationPair
        The job's pairs, with the camera the result goes with.
    T_camera_lidar : ndarray of shape (4, 4)
        The result.
    config : RefineConfig
        The cost's settings.
    tolerance : float
        Focal deviations up to this fraction are not flagged (``assess.intrinsics_tolerance``).
    """
    import math

    from nbcalib.registration.intrinsics import MIN_PAIRS, identifiability
    from nbcalib.transforms import se3_exp

    nan = math.nan
    if len(pairs) < MIN_PAIRS or pairs[0].camera.model == "equirectangular":
        why = (
            "an equirectangular camera has no focal length"
            if pairs[0].camera.model == "equirectangular"
            else f"{len(pairs)} pair(s): at least {MIN_PAIRS} frames at several depths tell a "
            "focal length from the camera's forward position"
        )
        return IntrinsicsCheck(False, True, nan, nan, nan, f"intrinsics not checked: {why}")
    T = np.asarray(T_camera_lidar, dtype=np.float64)
    fraction, step = _along(pairs, T, identifiability(pairs, T, [0.0], config)["newton"], config)
    # the bound where the joint minimum lies: away from it the pairs disagree about the pose
    # because the focal length is wrong, and their scatter says that, not the bound
    found = identifiability(pairs, se3_exp(fraction * step[:6]) @ T, fraction * step[6:], config)
    scale = math.exp(float(fraction * step[6]))
    bound = found["focal_bound_percent"]
    off = 100.0 * (scale - 1.0)
    agrees = abs(off) <= 100.0 * tolerance or abs(off) <= bound
    if agrees:
        note = (
            f"the given focal length agrees with the data ({off:+.2f} % +- {bound:.2f} %, "
            f"within {100 * tolerance:g} % or its bound)"
        )
    else:
        note = (
            f"the given focal length looks {off:+.2f} % off (+- {bound:.2f} %): the pose has "
            "absorbed it; check the camera's intrinsics, or refine them with the extrinsic "
            "(refine.intrinsics focal)"
        )
    return IntrinsicsCheck(True, agrees, scale, bound, found["correlation"], note)
