"""Fine registration (paper section III-E): hidden-point removal, then NID minimisation, repeated.

Each outer iteration

1. removes, per pair, the LiDAR points the camera cannot see from the current pose (a z-buffer
   at the camera's resolution; points more than ``depth_margin`` behind the nearest point in
   their pixel, or ``window`` pixels around it, are hidden);
2. minimises the NID summed over the pairs in a trust box around the current pose (L-BFGS on the
   B-spline NID with its exact gradient, or Nelder-Mead on the hard-binned NID as the paper);
3. stops when the pose moved less than ``converge_translation`` and ``converge_rotation_deg``.

The reference toolbox stops on 0.1 m / 0.5 degree changes; that lets a run stop 5 cm from where
the next iteration would go, so nbcalib's defaults are 1 mm / 0.01 degree.

Example
-------
>>> pairs = [RegistrationPair(camera, image, points_lidar, intensities)]   # doctest: +SKIP
>>> result = refine(pairs, T_camera_lidar_init)                              # doctest: +SKIP
>>> result.T_camera_lidar, result.history[-1].nid                            # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.registration.nid import MultiNIDCost, NIDCost
from nbcalib.registration.optimize import InnerResult, minimize_lbfgs, minimize_nelder_mead
from nbcalib.transforms import invert_T, pose_error, validate_T

__all__ = ["OuterIteration", "RefineConfig", "RefineResult", "RegistrationPair", "refine"]


@dataclass(frozen=True)
class RefineConfig:
    """Settings of fine registration; defaults follow the reference toolbox where sensible.

    Attributes
    ----------
    optimizer : {"lbfgs", "nelder_mead"}
        L-BFGS on the smooth NID (reference default: BFGS) or Nelder-Mead on the hard NID (paper).
    bins : int
        Histogram bins per axis (16).
    hidden_point_removal : bool
        Run the z-buffer visibility test before each outer iteration.
    depth_margin : float
        Metres behind the nearest point in a pixel that still count as visible (0.1).
    window : int
        Half-size of the pixel neighbourhood of the visibility test (0 = own pixel).
    max_outer : int
        Outer iterations at most (10).
    max_translation, max_rotation_deg : float
        Trust box of one outer iteration around its start pose (0.2 m, 2 degrees).
    converge_translation, converge_rotation_deg : float
        Stop when an outer iteration moves the pose less than both.
    max_inner : int
        Iterations (L-BFGS) or, times 40, evaluations (Nelder-Mead) per outer iteration.
    nelder_mead_init_step : float
        Initial simplex size in the tangent space (reference: 1e-3).
    """

    optimizer: str = "lbfgs"
    bins: int = 16
    hidden_point_removal: bool = True
    depth_margin: float = 0.1
    window: int = 0
    max_outer: int = 10
    max_translation: float = 0.2
    max_rotation_deg: float = 2.0
    converge_translation: float = 1e-3
    converge_rotation_deg: float = 0.01
    max_inner: int = 50
    nelder_mead_init_step: float = 1e-3

    def __post_init__(self):
        if self.optimizer not in ("lbfgs", "nelder_mead"):
            raise ValueError(f"optimizer must be 'lbfgs' or 'nelder_mead', got {self.optimizer!r}")
        for name in ("max_translation", "max_rotation_deg", "depth_margin"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0")
        if self.max_outer < 1 or self.max_inner < 1:
            raise ValueError("max_outer and max_inner must be >= 1")


@dataclass
class RegistrationPair:
    """One LiDAR-camera pair: a camera, its grey image, and the dense LiDAR cloud.

    Parameters
    ----------
    camera : CameraModel
    image : ndarray of shape (H, W), uint8 or float in [0, 1]
        Grey (equalised) camera image.
    points_lidar : ndarray of shape (N, 3), float
        Dense cloud in the LiDAR frame, metres.
    intensities : ndarray of shape (N,), float in [0, 1]
        Equalised LiDAR intensities.
    name : str, optional
    """

    camera: CameraModel
    image: np.ndarray
    points_lidar: np.ndarray
    intensities: np.ndarray
    name: str = ""


@dataclass
class OuterIteration:
    """What one outer iteration did."""

    nid: float
    nid_start: float
    visible_points: list[int]
    iterations: int
    evaluations: int
    translation_change: float
    rotation_change_deg: float
    seconds: float
    message: str


@dataclass
class RefineResult:
    """Result of :func:`refine`: the pose, the per-iteration history and totals."""

    T_camera_lidar: np.ndarray
    history: list[OuterIteration] = field(default_factory=list)
    converged: bool = False

    @property
    def nid(self) -> float:
        """Final summed NID."""
        return self.history[-1].nid if self.history else math.nan

    @property
    def evaluations(self) -> int:
        """Cost evaluations over all outer iterations."""
        return sum(h.evaluations for h in self.history)

    @property
    def iterations(self) -> int:
        """Inner iterations over all outer iterations."""
        return sum(h.iterations for h in self.history)


def visible_subset(pair: RegistrationPair, T_camera_lidar, config: RefineConfig) -> np.ndarray:
    """Indices of the pair's points that the camera sees from ``T_camera_lidar``."""
    from nbcalib.preprocess.lidar_image import visible_mask

    if not config.hidden_point_removal:
        _, valid = pair.camera.project(
            pair.points_lidar @ T_camera_lidar[:3, :3].T + T_camera_lidar[:3, 3], in_image=True
        )
        return np.flatnonzero(valid)
    mask = visible_mask(
        pair.camera,
        T_camera_lidar,
        pair.points_lidar,
        margin=config.depth_margin,
        window=config.window,
    )
    return np.flatnonzero(mask)


def build_cost(pairs: Sequence[RegistrationPair], T_camera_lidar, config: RefineConfig):
    """The summed NID over the points of each pair visible from ``T_camera_lidar``."""
    form = "smooth" if config.optimizer == "lbfgs" else "hard"
    costs, counts = [], []
    for pair in pairs:
        keep = visible_subset(pair, T_camera_lidar, config)
        counts.append(int(keep.size))
        costs.append(
            NIDCost(
                pair.camera,
                pair.image,
                pair.points_lidar[keep],
                np.asarray(pair.intensities)[keep],
                bins=config.bins,
                form=form,
            )
        )
    return MultiNIDCost(costs), counts


def refine(
    pairs: Sequence[RegistrationPair],
    T_camera_lidar_init,
    config: RefineConfig | None = None,
    *,
    progress: Callable[[int, OuterIteration], None] | None = None,
) -> RefineResult:
    """Refine ``T_camera_lidar`` by NID minimisation with hidden-point removal.

    Parameters
    ----------
    pairs : sequence of RegistrationPair
        One or more LiDAR-camera pairs that share the extrinsic.
    T_camera_lidar_init : array_like of shape (4, 4)
        Initial guess, ``p_camera = T_camera_lidar @ p_lidar``.
    config : RefineConfig, optional
    progress : callable, optional
        Called as ``progress(outer_index, OuterIteration)`` after each outer iteration.

    Returns
    -------
    RefineResult
    """
    config = config or RefineConfig()
    if not pairs:
        raise ValueError("refine needs at least one LiDAR-camera pair")
    T = validate_T(np.asarray(T_camera_lidar_init, dtype=np.float64), "T_camera_lidar_init")
    result = RefineResult(T.copy())
    max_rot = math.radians(config.max_rotation_deg)
    for outer in range(config.max_outer):
        t0 = time.perf_counter()
        cost, counts = build_cost(pairs, T, config)
        if sum(counts) == 0:
            raise ValueError("no LiDAR point projects into any image at the current pose")
        start_value = cost.value(T)
        inner: InnerResult
        if config.optimizer == "lbfgs":
            inner = minimize_lbfgs(
                cost.value_and_grad,
                T,
                max_translation=config.max_translation,
                max_rotation=max_rot,
                max_iterations=config.max_inner,
            )
        else:
            inner = minimize_nelder_mead(
                cost.value,
                T,
                init_step=config.nelder_mead_init_step,
                max_translation=config.max_translation,
                max_rotation=max_rot,
                max_evaluations=40 * config.max_inner,
            )
        T_new = inner.T_camera_lidar
        if inner.value > start_value:  # never accept a worse pose
            T_new, inner.value = T, start_value
        dt, dr = pose_error(invert_T(T_new), invert_T(T))
        step = OuterIteration(
            nid=inner.value,
            nid_start=start_value,
            visible_points=counts,
            iterations=inner.iterations,
            evaluations=inner.evaluations,
            translation_change=float(dt),
            rotation_change_deg=float(dr),
            seconds=time.perf_counter() - t0,
            message=inner.message,
        )
        result.history.append(step)
        T = T_new
        result.T_camera_lidar = T.copy()
        if progress is not None:
            progress(outer, step)
        if dt < config.converge_translation and dr < config.converge_rotation_deg:
            result.converged = True
            break
    return result
