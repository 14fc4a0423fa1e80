"""The cost fine registration minimises: chosen by settings, built from terms, in one place.

For each pair the cost looks at the points the camera sees from the pose it is built at (the
*anchor*: the start of an outer iteration), at most ``points_per_pixel`` of them
(:class:`PairView`), and sums weighted **terms** over the pairs:

- the **intensity term**, chosen by :attr:`RefineConfig.cost
  <nbcalib.registration.config.RefineConfig>` (a name of
  :data:`~nbcalib.registration.config.COSTS`, each one module here):

  - ``"regional"`` (:mod:`~nbcalib.registration.costs.regional`): the image is cut into
    regions of about ``region_points`` points each at the anchor, one joint histogram per
    region, the mean of their NIDs;
  - ``"nid"`` (:mod:`~nbcalib.registration.costs.nid`): one joint histogram per pair (the
    paper, the reference toolbox), or one per class of surface orientation;

- the **structure term** (:mod:`~nbcalib.registration.costs.structure`), with the weight
  ``structure_weight`` (0: off): LiDAR depth edges against image edges.

Every term is an object with ``evaluate(T, grad=False)`` returning a
:class:`~nbcalib.registration.nid.NIDEvaluation`, ``value(T)``, ``value_and_grad(T)``,
``len()`` (its points) and a settable ``parallel``; :func:`build_cost` returns their weighted
sum, a :class:`~nbcalib.registration.nid.MultiNIDCost`, and the number of visible points of
each pair. Fine registration (:mod:`nbcalib.registration.refine`), the quality report
(:mod:`nbcalib.report.quality`), the warm-up (:mod:`nbcalib.warmup_job`) and the records in
``calib.json`` all go through :func:`build_cost`, so a new cost is a module here, a name in
:data:`~nbcalib.registration.config.COSTS` and its setting, and nothing else changes.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from nbcalib._threads import thread_map
from nbcalib.registration.config import COSTS, RefineConfig

if TYPE_CHECKING:  # the kernels load with the first cost built, not with this module
    from nbcalib.camera import CameraModel
    from nbcalib.registration.nid import MultiNIDCost

__all__ = ["COSTS", "PairView", "RigTerm", "build_cost", "pair_view", "point_budget"]


@dataclass
class PairView:
    """What a term sees of one pair at one pose and pyramid level.

    Attributes
    ----------
    pair : RegistrationPair
        The pair (camera, image, cloud, intensities, and the caches of normals and edges).
    T_camera_lidar : ndarray of shape (4, 4)
        The pose the cost is built at (the anchor).
    keep : ndarray of int64
        Indices of the points the terms use: visible from the anchor, at most the
        ``points_per_pixel`` budget, in pixel order.
    n_visible : int
        Visible points before the budget.
    level : int
        Pyramid level: the terms use ``camera`` and ``image``, the full resolution averaged
        over ``2^level`` pixel blocks.
    camera : CameraModel
    image : ndarray of shape (H, W), uint8
    form : {"smooth", "hard"}
        The NID form the optimiser needs (hard: Nelder-Mead; smooth: L-BFGS and the report).
    """

    pair: object
    T_camera_lidar: np.ndarray
    keep: np.ndarray
    n_visible: int
    level: int
    camera: CameraModel
    image: np.ndarray
    form: str

    @property
    def points(self) -> np.ndarray:
        """The kept points (K, 3), LiDAR frame."""
        return self.pair.rows(self.keep)[0]

    @property
    def intensities(self) -> np.ndarray:
        """Their intensities (K,), in [0, 1]."""
        return self.pair.rows(self.keep)[1]

    def anchor_pixels(self) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (K, 2) of the kept points at the anchor, full resolution, and their validity."""
        T = self.T_camera_lidar
        return self.pair.camera.project(self.points @ T[:3, :3].T + T[:3, 3])


def point_budget(camera: CameraModel, config: RefineConfig, n_pairs: int = 1) -> float | None:
    """Points one pair of a job of ``n_pairs`` pairs uses at most (None: every visible one).

    ``points_per_pixel`` of ``camera``'s pixels, at least ``min_sampled_points``; and at most
    an equal share of ``job_points``, never below ``min_sampled_points``
    (:class:`~nbcalib.registration.config.RefineConfig`).
    """
    budget = None
    if config.points_per_pixel is not None:
        pixels = camera.width * camera.height
        budget = max(config.points_per_pixel * pixels, config.min_sampled_points)
    if config.job_points is not None:
        share = max(config.job_points / max(n_pairs, 1), config.min_sampled_points)
        budget = share if budget is None else min(budget, share)
    return budget


def pair_view(
    pair, T_camera_lidar, config: RefineConfig, *, level: int = 0, n_pairs: int = 1
) -> PairView:
    """The points of ``pair`` the terms use at ``T_camera_lidar`` (:class:`PairView`).

    ``n_pairs``: how many pairs the job has (:func:`point_budget`).
    """
    from nbcalib.registration.pair import downscale_camera, downscale_image, visible_subset

    full = pair.camera
    budget = point_budget(full, config, n_pairs)
    n_visible = 0  # before the subset

    def subset(visible):
        nonlocal n_visible
        n_visible = visible.size
        return pair.sample(visible, budget)

    # the subset is drawn before the visible points are sorted by pixel: a sort of far fewer
    # points, and the same result as sampling the sorted ones
    keep = visible_subset(pair, T_camera_lidar, config, select=subset)
    return PairView(
        pair=pair,
        T_camera_lidar=np.asarray(T_camera_lidar, dtype=np.float64),
        keep=keep,
        n_visible=int(n_visible),
        level=level,
        camera=downscale_camera(full, level),
        image=downscale_image(pair.image, level),
        # the hybrid ends with L-BFGS: its result is judged by the smooth form
        form="hard" if config.optimizer == "nelder_mead" else "smooth",
    )


def se3_adjoint(T) -> np.ndarray:
    """``Ad_T`` (6 x 6) for ``delta = [v, omega]``: ``T exp(delta) T^-1 = exp(Ad_T delta)``."""
    from nbcalib.transforms import hat

    R, t = np.asarray(T[:3, :3], dtype=np.float64), np.asarray(T[:3, 3], dtype=np.float64)
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = R
    Ad[:3, 3:] = hat(t) @ R
    Ad[3:, 3:] = R
    return Ad


class RigTerm:
    """A term of a pair whose camera is another camera of a rig, as a function of the rig's pose.

    The optimised pose is the rig's reference camera's ``T_ref_lidar``; this pair's camera sees
    the cloud at ``T_camera_ref @ T_ref_lidar``. The gradient with respect to a left
    perturbation of ``T_ref_lidar`` is the term's own through the adjoint:
    ``T_camera_ref exp(d) = exp(Ad d) T_camera_ref``, so ``d/dd = Ad^T g``.
    """

    def __init__(self, term, T_camera_ref):
        self.term = term
        self.T_camera_ref = np.asarray(T_camera_ref, dtype=np.float64)
        self._adjoint_T = se3_adjoint(self.T_camera_ref).T

    def evaluate(self, T_camera_lidar, *, grad: bool = False, intrinsics=None):
        """The term at the pair camera's pose (and the gradient in the reference camera's)."""
        from nbcalib.registration.nid import NIDEvaluation

        if intrinsics is not None:
            raise ValueError("a rig's intrinsics cannot be refined with its extrinsic")
        ev = self.term.evaluate(self.T_camera_ref @ T_camera_lidar, grad=grad)
        g = None if ev.grad is None else self._adjoint_T @ ev.grad
        return NIDEvaluation(ev.value, g, ev.n_in_image)

    def value(self, T_camera_lidar) -> float:
        """The term's value."""
        return self.evaluate(T_camera_lidar).value

    def value_and_grad(self, T_camera_lidar) -> tuple[float, np.ndarray]:
        """The term's value and gradient."""
        ev = self.evaluate(T_camera_lidar, grad=True)
        return ev.value, ev.grad

    def __len__(self) -> int:
        return len(self.term)

    @property
    def parallel(self):
        """The term's own setting."""
        return self.term.parallel

    @parallel.setter
    def parallel(self, value) -> None:
        self.term.parallel = value


def build_cost(
    pairs: Sequence,
    T_camera_lidar,
    config: RefineConfig,
    *,
    level: int = 0,
    n_pairs: int | None = None,
) -> tuple[MultiNIDCost, list[int]]:
    """The summed cost over ``pairs`` at the points visible from ``T_camera_lidar``.

    Visibility is tested with the full-resolution camera; the terms use pyramid ``level``.
    ``n_pairs``: the pairs of the whole job, when ``pairs`` are some of them (default: their
    number), for each pair's share of ``job_points`` (:func:`point_budget`).
    Each pair adds its intensity term (:attr:`RefineConfig.cost`, weight 1) and, when
    ``structure_weight > 0``, its structure term times that weight. A pair of another camera of
    a rig (``pair.T_camera_rig`` set) is looked at from ``T_camera_rig @ T_camera_lidar``, its
    terms as functions of ``T_camera_lidar`` (:class:`RigTerm`).

    Returns
    -------
    cost : MultiNIDCost
        The weighted sum of every pair's terms.
    counts : list of int
        Visible points of each pair (before the ``points_per_pixel`` subset).
    """
    from nbcalib.registration.costs import structure
    from nbcalib.registration.nid import MultiNIDCost

    intensity = importlib.import_module(COSTS[config.cost]).terms
    n_pairs = n_pairs or len(pairs)

    def pair_terms(pair):  # one pair's z-buffer, subset and terms: independent of the others
        offset = getattr(pair, "T_camera_rig", None)
        T = T_camera_lidar if offset is None else offset @ np.asarray(T_camera_lidar)
        with pair.held():  # a cloud read from the work directory: once for all of this
            view = pair_view(pair, T, config, level=level, n_pairs=n_pairs)
            terms = intensity(view, config)
            if config.structure_weight > 0 and view.keep.size:
                weight = config.structure_weight
                terms += [(t, w * weight) for t, w in structure.terms(view, config)]
        if offset is not None:
            terms = [(RigTerm(t, offset), w) for t, w in terms]
        return view.n_visible, terms

    costs, weights, counts = [], [], []
    for n_visible, terms in thread_map(pair_terms, pairs):  # pairs on every core
        counts.append(n_visible)
        for term, weight in terms:
            costs.append(term)
            weights.append(weight)
    return MultiNIDCost(costs, weights), counts
