"""The NID cost between LiDAR intensities and the camera image, as a function of ``T_camera_lidar``.

NID, the normalised information distance (paper Eq. 2-4), is 0 when the LiDAR intensities predict
the image intensities at their projections perfectly and 1 when they share no information. It
compares co-occurrences, not values, so it bridges the gap between LiDAR reflectivity and camera
brightness.

Two forms (``form=``):

``"hard"``
    each point samples its nearest pixel; integer joint histogram; piecewise constant in the pose,
    so only derivative-free optimisers (Nelder-Mead, as the paper) apply.
``"smooth"`` (default)
    each point spreads over the 4 x 4 pixels around it with cubic B-spline weights (the reference
    toolbox's default), which makes the cost differentiable; :meth:`NIDCost.value_and_grad` returns
    the exact gradient with respect to a left perturbation ``T <- exp(delta) T``,
    ``delta = [v, omega]`` (docs/conventions.md).

Intensities are hard-binned in both forms: ``bin = min(int(v * bins), bins - 1)`` for LiDAR
intensities and image values in [0, 1].

Example
-------
>>> cost = NIDCost(camera, image, points_lidar, intensities)      # doctest: +SKIP
>>> value, grad = cost.value_and_grad(T_camera_lidar)              # doctest: +SKIP
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.kernels import nid as _k

__all__ = ["GroupedNIDCost", "MultiNIDCost", "NIDCost", "quantise"]


def quantise(values, bins: int) -> np.ndarray:
    """Bin indices (uint8) of values in [0, 1]: ``min(int(v * bins), bins - 1)``; NaN -> 0."""
    if not 1 <= bins <= 256:
        raise ValueError(f"bins must be in [1, 256], got {bins}")
    arr = np.ascontiguousarray(values, dtype=np.float64)
    return _k._quantise(arr, int(bins))


def _image_to_unit(image) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image must be a 2-D grey image, got shape {img.shape}")
    if img.dtype == np.uint8:
        return img / 255.0
    if img.dtype == np.uint16:
        return img / 65535.0
    img = img.astype(np.float64)
    if not np.all(np.isfinite(img)) or img.min() < 0.0 or img.max() > 1.0:
        raise ValueError("a float image must hold finite values in [0, 1]")
    return img


def offset_params(camera: CameraModel, intrinsics, level: int = 0):
    """The kernels' camera parameters with an intrinsics offset, and its size.

    ``intrinsics`` (issue 47; None or empty: the camera as it is): ``[lambda]`` scales ``fx`` and
    ``fy`` by ``exp(lambda)``; ``[lambda, dcx, dcy]`` also moves the principal point by ``dcx,
    dcy`` pixels of the full resolution, of which ``camera``, at pyramid ``level``, has
    ``2^-level``. Returns ``(params, n_intr, center_step)`` for the smooth kernel, whose
    derivative then has ``6 + n_intr`` columns (:func:`nbcalib.kernels.nid.
    _joint_hist_smooth_impl`).
    """
    center_step = 2.0**-level
    if intrinsics is None or len(intrinsics) == 0:
        return camera.params, 0, center_step
    offset = np.asarray(intrinsics, dtype=np.float64).ravel()
    if offset.size not in (1, 3) or not np.all(np.isfinite(offset)):
        raise ValueError(f"an intrinsics offset has 1 or 3 finite values, got {offset.tolist()}")
    if camera.model == "equirectangular":
        raise ValueError("an equirectangular camera has no focal length or principal point")
    params = camera.params.copy()
    params[0:2] *= math.exp(offset[0])
    if offset.size == 3:
        params[2:4] += offset[1:] * center_step
    return params, offset.size, center_step


@dataclass(frozen=True)
class NIDEvaluation:
    """One evaluation: the NID value, its gradient (or None) and how many points were in view.

    The gradient has six entries (the pose's ``delta = [v, omega]``), and one or three more when
    the evaluation was asked with an intrinsics offset (:func:`offset_params`).
    """

    value: float
    grad: np.ndarray | None
    n_in_image: int


class NIDCost:
    """NID between one LiDAR cloud and one camera image, as a function of ``T_camera_lidar``.

    Parameters
    ----------
    camera : CameraModel
        The camera that took ``image``.
    image : ndarray of shape (H, W), uint8, uint16 or float in [0, 1]
        Grey camera image (usually histogram-equalised).
    points_lidar : ndarray of shape (N, 3), float
        LiDAR points in the LiDAR frame (usually the ones visible from the camera after
        hidden-point removal), metres.
    intensities : ndarray of shape (N,), float in [0, 1]
        LiDAR intensities (usually rank-equalised).
    bins : int, optional
        Histogram bins per axis (paper and reference: 16).
    form : {"smooth", "hard"}, optional
        B-spline smoothed with exact gradient, or nearest-pixel (see module docstring).
    parallel : bool, optional
        Use the multithreaded kernel (identical results; faster for large clouds).
    level : int, optional
        The pyramid level ``camera`` and ``image`` belong to (0: full resolution): an
        intrinsics offset's principal point is in pixels of the full resolution.
    """

    def __init__(
        self,
        camera: CameraModel,
        image,
        points_lidar,
        intensities,
        *,
        bins: int = 16,
        form: str = "smooth",
        parallel: bool = True,
        level: int = 0,
    ):
        if form not in ("smooth", "hard"):
            raise ValueError(f"form must be 'smooth' or 'hard', got {form!r}")
        img = _image_to_unit(image)
        if img.shape != (camera.height, camera.width):
            raise ValueError(
                f"image is {img.shape[1]} x {img.shape[0]} but the camera is "
                f"{camera.width} x {camera.height}"
            )
        pts = np.ascontiguousarray(points_lidar, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points_lidar must have shape (N, 3), got {pts.shape}")
        inten = np.ascontiguousarray(intensities, dtype=np.float64).ravel()
        if inten.shape[0] != pts.shape[0]:
            raise ValueError(f"{inten.shape[0]} intensities for {pts.shape[0]} points")
        finite = np.isfinite(pts).all(axis=1) & np.isfinite(inten)
        self.camera = camera
        self.level = int(level)
        self.bins = int(bins)
        self.form = form
        self.parallel = bool(parallel)
        # coordinate rows (3, N): the kernels read x, y and z as separate contiguous arrays
        self.xyz = np.ascontiguousarray(pts[finite].T)
        self.point_bins = quantise(inten[finite], self.bins)
        self.image_bins = quantise(img, self.bins)
        self._padded = _k.padded_image_bins(self.image_bins, self.bins) if form == "hard" else None

    @property
    def points(self) -> np.ndarray:
        """The finite LiDAR points (N, 3) the cost uses (a view of :attr:`xyz`)."""
        return self.xyz.T

    def __len__(self) -> int:
        return self.xyz.shape[1]

    def evaluate(self, T_camera_lidar, *, grad: bool = False, intrinsics=None) -> NIDEvaluation:
        """NID at ``T_camera_lidar`` (4 x 4), with the gradient if ``grad`` (smooth form only).

        ``intrinsics``: an offset of the camera's intrinsics (:func:`offset_params`); the
        gradient then has its columns after the pose's six.
        """
        T = np.ascontiguousarray(T_camera_lidar, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("T_camera_lidar must be a finite 4 x 4 matrix")
        cam = self.camera
        params, n_intr, center_step = offset_params(cam, intrinsics, self.level)
        if self.form == "hard":
            if grad:
                raise ValueError("the hard-binned NID is piecewise constant: it has no gradient")
            hist = _k.joint_hist_hard(
                cam.model_id,
                params,
                T,
                self.xyz,
                self.point_bins,
                self.image_bins,
                self.bins,
                parallel=self.parallel,
                padded=self._padded,
            ).astype(np.float64)
            n_in = int(hist.sum())
            value, _ = _k._nid_from_hist(hist, np.zeros((self.bins, self.bins, 6)), False)
            return NIDEvaluation(float(value), None, n_in)
        kernel = _k._joint_hist_smooth_parallel if self.parallel else _k._joint_hist_smooth
        hist, dhist, n_in = kernel(
            cam.model_id,
            params,
            T,
            self.xyz,
            self.point_bins,
            self.image_bins,
            self.bins,
            self.bins,
            _k.N_CHUNKS,
            grad,
            n_intr,
            center_step,
        )
        value, g = _k._nid_from_hist(hist, dhist, grad)
        return NIDEvaluation(float(value), g if grad else None, int(n_in))

    def value(self, T_camera_lidar, intrinsics=None) -> float:
        """NID at ``T_camera_lidar``."""
        return self.evaluate(T_camera_lidar, intrinsics=intrinsics).value

    def value_and_grad(self, T_camera_lidar, intrinsics=None) -> tuple[float, np.ndarray]:
        """NID and its gradient (6,) w.r.t. ``delta = [v, omega]`` in ``exp(delta) @ T``."""
        ev = self.evaluate(T_camera_lidar, grad=True, intrinsics=intrinsics)
        return ev.value, ev.grad


class GroupedNIDCost:
    """The mean of the NIDs of groups of points, each group with a joint histogram of its own.

    ``sum_g w_g NID_g(T)``, ``w_g`` the share of the points in group ``g`` (fixed when the cost
    is made, not recounted at each pose): the cost of
    :mod:`nbcalib.registration.costs.regional`, where a group is a region of the image. One
    kernel call fills every group's histogram (stacked rows, :func:`nbcalib.kernels.nid.
    grouped_rows`); the points are stored sorted by group, in their given order within it.

    Parameters
    ----------
    camera, image, points_lidar, intensities, bins, form, parallel
        As :class:`NIDCost`.
    groups : ndarray of shape (N,), int
        Group of each point (any integers; groups are numbered in sorted order).
    level : int, optional
        As :class:`NIDCost`.
    """

    def __init__(
        self,
        camera: CameraModel,
        image,
        points_lidar,
        intensities,
        groups,
        *,
        bins: int = 16,
        form: str = "smooth",
        parallel: bool = True,
        level: int = 0,
    ):
        if form not in ("smooth", "hard"):
            raise ValueError(f"form must be 'smooth' or 'hard', got {form!r}")
        img = _image_to_unit(image)
        if img.shape != (camera.height, camera.width):
            raise ValueError(
                f"image is {img.shape[1]} x {img.shape[0]} but the camera is "
                f"{camera.width} x {camera.height}"
            )
        pts = np.ascontiguousarray(points_lidar, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"points_lidar must have shape (N, 3), got {pts.shape}")
        inten = np.ascontiguousarray(intensities, dtype=np.float64).ravel()
        groups = np.asarray(groups).ravel()
        if inten.shape[0] != pts.shape[0] or groups.shape[0] != pts.shape[0]:
            raise ValueError(
                f"{inten.shape[0]} intensities and {groups.shape[0]} groups for "
                f"{pts.shape[0]} points"
            )
        finite = np.isfinite(pts).all(axis=1) & np.isfinite(inten)
        _, group_ids = np.unique(groups[finite], return_inverse=True)
        group_ids = group_ids.ravel()
        order = np.argsort(group_ids, kind="stable")
        self.camera = camera
        self.level = int(level)
        self.bins = int(bins)
        self.form = form
        self.parallel = bool(parallel)
        self.xyz = np.ascontiguousarray(pts[finite][order].T)
        self.group_of_point = group_ids[order]  # sorted, 0 .. n_groups - 1
        point_bins = quantise(inten[finite][order], self.bins)
        self.rows = _k.grouped_rows(group_ids[order], point_bins, self.bins)
        counts = np.bincount(group_ids, minlength=1).astype(np.float64)
        self.n_groups = counts.size
        self.weights = counts / max(counts.sum(), 1.0)
        self.image_bins = quantise(img, self.bins)
        self._padded = _k.padded_image_bins(self.image_bins, self.bins) if form == "hard" else None

    @property
    def points(self) -> np.ndarray:
        """The finite LiDAR points (N, 3), sorted by group (a view of :attr:`xyz`)."""
        return self.xyz.T

    def __len__(self) -> int:
        return self.xyz.shape[1]

    def evaluate(self, T_camera_lidar, *, grad: bool = False, intrinsics=None) -> NIDEvaluation:
        """The groups' mean NID at ``T_camera_lidar`` (4 x 4), with the gradient if ``grad``.

        ``intrinsics``: as :meth:`NIDCost.evaluate`.
        """
        T = np.ascontiguousarray(T_camera_lidar, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("T_camera_lidar must be a finite 4 x 4 matrix")
        if self.form == "hard":
            cam = self.camera
            if grad:
                raise ValueError("the hard-binned NID is piecewise constant: it has no gradient")
            params, _, _ = offset_params(cam, intrinsics, self.level)
            hist = _k.joint_hist_hard(
                cam.model_id,
                params,
                T,
                self.xyz,
                self.rows,
                self.image_bins,
                self.bins,
                parallel=self.parallel,
                padded=self._padded,
                groups=self.n_groups,
            ).astype(np.float64)
            value, _ = _k._grouped_nid(
                hist, np.zeros((1, self.bins, 6)), self.bins, self.weights, False
            )
            return NIDEvaluation(float(value), None, int(hist.sum()))
        hist, dhist, n_in = self._smooth_histograms(T, grad, intrinsics)
        value, g = _k._grouped_nid(hist, dhist, self.bins, self.weights, grad)
        return NIDEvaluation(float(value), g if grad else None, int(n_in))

    def _smooth_histograms(self, T: np.ndarray, grad: bool, intrinsics=None):
        """The stacked B-spline joint histograms (and their derivatives if ``grad``) at ``T``."""
        cam = self.camera
        params, n_intr, center_step = offset_params(cam, intrinsics, self.level)
        kernel = _k._joint_hist_smooth_parallel if self.parallel else _k._joint_hist_smooth
        return kernel(
            cam.model_id,
            params,
            T,
            self.xyz,
            self.rows,
            self.image_bins,
            self.bins,
            self.n_groups * self.bins,
            _k.N_CHUNKS,
            grad,
            n_intr,
            center_step,
        )

    def each_group(self, T_camera_lidar, intrinsics=None) -> tuple[np.ndarray, np.ndarray]:
        """Each group's own NID (G,) and its gradient (G, 6 [+ 1 or 3]) at a pose, unweighted.

        The smooth form's terms of :meth:`value_and_grad` before the weights
        (:attr:`weights`) sum them; the quality report's jackknife over regions uses them
        (:mod:`nbcalib.report.quality`).
        """
        if self.form != "smooth":
            raise ValueError("each_group needs the smooth form (the hard one has no gradient)")
        T = np.ascontiguousarray(T_camera_lidar, dtype=np.float64)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError("T_camera_lidar must be a finite 4 x 4 matrix")
        hist, dhist, _ = self._smooth_histograms(T, True, intrinsics)
        return _k._each_group_nid(hist, dhist, self.bins, self.n_groups, True)

    def value(self, T_camera_lidar, intrinsics=None) -> float:
        """The groups' mean NID at ``T_camera_lidar``."""
        return self.evaluate(T_camera_lidar, intrinsics=intrinsics).value

    def value_and_grad(self, T_camera_lidar, intrinsics=None) -> tuple[float, np.ndarray]:
        """The groups' mean NID and its gradient (6,) w.r.t. ``delta`` in ``exp(delta) @ T``."""
        ev = self.evaluate(T_camera_lidar, grad=True, intrinsics=intrinsics)
        return ev.value, ev.grad


class MultiNIDCost:
    """Weighted sum of NID costs that share one ``T_camera_lidar`` (pairs, orientation classes).

    Parameters
    ----------
    costs : sequence of NIDCost
    weights : sequence of float, optional
        Weight of each cost (default: all 1, the plain sum over pairs).
    """

    def __init__(self, costs: Sequence[NIDCost], weights: Sequence[float] | None = None):
        if not costs:
            raise ValueError("MultiNIDCost needs at least one pair")
        self.costs = list(costs)
        w = np.ones(len(self.costs)) if weights is None else np.asarray(weights, dtype=np.float64)
        if w.shape != (len(self.costs),) or not np.all(np.isfinite(w)) or np.any(w < 0):
            raise ValueError(f"weights must be {len(self.costs)} finite values >= 0")
        self.weights = w

    def evaluate(self, T_camera_lidar, *, grad: bool = False, intrinsics=None) -> NIDEvaluation:
        """Weighted NID sum (and gradient) over the costs (``intrinsics``: their offset)."""
        if intrinsics is None:  # terms that know nothing of intrinsics (a rig's) stay valid
            evs = [c.evaluate(T_camera_lidar, grad=grad) for c in self.costs]
        else:
            evs = [c.evaluate(T_camera_lidar, grad=grad, intrinsics=intrinsics) for c in self.costs]
        value = float(sum(w * e.value for w, e in zip(self.weights, evs)))
        g = np.sum([w * e.grad for w, e in zip(self.weights, evs)], axis=0) if grad else None
        return NIDEvaluation(value, g, sum(e.n_in_image for e in evs))

    def value(self, T_camera_lidar, intrinsics=None) -> float:
        """Weighted NID sum."""
        return self.evaluate(T_camera_lidar, intrinsics=intrinsics).value

    def value_and_grad(self, T_camera_lidar, intrinsics=None) -> tuple[float, np.ndarray]:
        """Weighted NID sum and gradient."""
        ev = self.evaluate(T_camera_lidar, grad=True, intrinsics=intrinsics)
        return ev.value, ev.grad
