"""One LiDAR-camera pair of fine registration: what it holds, what its camera sees, its pyramid.

:class:`RegistrationPair` (a camera, its grey image, the dense cloud, and what is computed once
per pair: visibility at the last poses, structure edges, orientation classes, a seeded sample);
:func:`visible_subset` (hidden-point removal at a pose); :func:`downscale_camera` and
:func:`downscale_image` (a level of the coarse-to-fine pyramid). The costs
(:mod:`nbcalib.registration.costs`) and the optimiser (:mod:`nbcalib.registration.refine`)
both build on this module; it imports neither.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nbcalib.camera import CameraModel, create_camera
from nbcalib.clouds import Cloud
from nbcalib.registration.config import RefineConfig

__all__ = ["RegistrationPair", "downscale_camera", "downscale_image", "visible_subset"]


class _Tree:
    """A KD-tree of a cloud's finite points, and those points' rows."""

    def __init__(self, points: np.ndarray):
        from nbcalib.registration.orientation import kdtree

        # non-finite points are dropped by the cost; they get class 0 and no neighbours
        self.finite = np.flatnonzero(np.isfinite(points).all(axis=1))
        self.tree = kdtree(points[self.finite]) if self.finite.size >= 3 else None
        # the tree copies the points (24 B), keeps an index each (8 B) and its nodes (~16 B)
        self.nbytes_estimate = int(self.finite.nbytes + 48 * self.finite.size)


@dataclass(init=False, eq=False)
class RegistrationPair:
    """One LiDAR-camera pair: a camera, its grey image, and the dense LiDAR cloud.

    Parameters
    ----------
    camera : CameraModel
    image : ndarray of shape (H, W), uint8 or float in [0, 1]
        Grey (equalised) camera image.
    points_lidar : ndarray of shape (N, 3), float, optional
        Dense cloud in the LiDAR frame, metres (or give ``cloud``).
    intensities : ndarray of shape (N,), float in [0, 1], optional
        Equalised LiDAR intensities.
    name : str, optional
    classes : ndarray of shape (N,), int8, optional
        Surface-orientation class of each point
        (:func:`~nbcalib.registration.orientation.orientation_classes`), -1 where not known
        yet; computed for the visible points on first use when None.
    T_camera_rig : ndarray of shape (4, 4), optional
        For a pair of another camera of a rig: this camera from the rig's reference camera,
        whose ``T_camera_lidar`` is refined (the pair is seen at ``T_camera_rig @ T``). None:
        the pair's camera is the one refined.
    cloud : Cloud, optional
        Instead of ``points_lidar`` and ``intensities``: the cloud, held or read from the work
        directory when needed (:mod:`nbcalib.clouds`). Pairs made from one another
        (``dataclasses.replace``) share it, and with it what is computed from the cloud, unless
        given new arrays.
    """

    camera: CameraModel
    image: np.ndarray
    cloud: Cloud = field(repr=False)
    name: str = ""
    T_camera_rig: np.ndarray | None = field(default=None, repr=False)

    def __init__(
        self,
        camera: CameraModel,
        image,
        points_lidar=None,
        intensities=None,
        name: str = "",
        classes=None,
        T_camera_rig=None,
        *,
        cloud: Cloud | None = None,
    ):
        cloud = Cloud.given(cloud, points_lidar, intensities, classes)
        self.camera = camera
        self.image = image
        self.cloud = cloud
        self.name = name
        self.T_camera_rig = T_camera_rig

    @property
    def points_lidar(self) -> np.ndarray:
        """The dense cloud (N, 3), LiDAR frame (read from its file if not held)."""
        return self.cloud.points

    @property
    def intensities(self) -> np.ndarray:
        """The intensities (N,), in [0, 1]."""
        return self.cloud.intensities

    @property
    def classes(self) -> np.ndarray | None:
        """Orientation classes known so far (-1: not yet), or None before the first ask."""
        return self.cloud.classes

    @classes.setter
    def classes(self, value) -> None:
        self.cloud.classes = None if value is None else np.asarray(value, dtype=np.int8)

    def __len__(self) -> int:
        return len(self.cloud)

    def rows(self, index) -> tuple[np.ndarray, np.ndarray]:
        """``(points_lidar[index], intensities[index])``, float64 (:meth:`Cloud.rows`)."""
        return self.cloud.rows(index)

    def held(self):
        """``with pair.held():`` reads the cloud once for the block (:meth:`Cloud.held`)."""
        return self.cloud.held()

    def visibility(self, T_camera_lidar, margin: float, window: int):
        """The visible points at one pose and their pixels, kept for later calls.

        :func:`~nbcalib.preprocess.lidar_image.visibility`, returned as ``(keep, pixel)``:
        the visible points' rows in cloud order (M,) and the flat pixel of each (M,), int32
        (int64 for a cloud or an image past 2^31), read-only: the same arrays for every call at
        this pose. The report asks for the visible set at the result four times (its cost, the
        pixels covered, the overlays) and at the start once: the z-buffer's answer is kept for
        the last two poses asked of the cloud (as the job's memory budget allows, in int32:
        15 MB a synthetic Livox pair of 2.2 M points). An older pose's is dropped before a new
        one is made, which then finds room.
        """
        from nbcalib.preprocess.lidar_image import visibility

        T = np.asarray(T_camera_lidar, dtype=np.float64)
        cloud, camera = self.cloud, self.camera
        key = ("visible", T.tobytes(), float(margin), int(window), id(camera))

        def make():
            # the stored values: float32 from a work directory, widened in the kernel (exact)
            points = cloud.stored()[0]
            keep, pixel = visibility(camera, T, points, margin=margin, window=window)
            small = len(cloud) < 2**31 and camera.width * camera.height < 2**31
            kind = np.int32 if small else np.int64
            rows, pixels = keep.astype(kind), pixel[keep].astype(kind)
            rows.flags.writeable = pixels.flags.writeable = False
            return camera, rows, pixels

        with cloud._lock:
            asked = [k for k in cloud.visible_keys if k != key] + [key]
            cloud.visible_keys = asked[-2:]
        for old in asked[:-2]:
            cloud.forget(old)
        entry = cloud.memo(key, make)
        if entry[0] is not camera:  # another camera at the same address: not this one's
            cloud.forget(key)
            entry = cloud.memo(key, make)
        return entry[1], entry[2]

    def structure(self) -> tuple[np.ndarray, np.ndarray]:
        """(depth-edge score per point, image edge strength): the structure channel, made once.

        :mod:`nbcalib.registration.structure`; both depend on the data only, not on the pose.
        """
        from nbcalib.registration.structure import depth_edge_scores, image_edges

        image = self.image
        scores = self.cloud.memo("depth_edges", lambda: depth_edge_scores(self.points_lidar))
        edges = self.cloud.memo(("image_edges", id(image)), lambda: (image, image_edges(image)))
        if edges[0] is not image:
            edges = (image, image_edges(image))
        return scores, edges[1]

    def sample(self, visible: np.ndarray, budget: float | None) -> np.ndarray:
        """About ``budget`` of the ``visible`` point indices (all of them if fewer), in order.

        A seeded random key per point (drawn the same for every cloud of its size) keeps the
        points whose key falls under the needed rate, so the subset is the same for every pose
        and nests across pyramid levels; None keeps them all.
        """
        if budget is None or visible.size <= budget:
            return visible
        n = len(self.cloud)
        keys = self.cloud.memo("keys", lambda: np.random.default_rng(0).random(n, dtype=np.float32))
        return visible[keys[visible] < budget / visible.size]

    def orientation_classes(self, indices=None) -> np.ndarray:
        """Orientation classes of the points ``indices`` (default all), each computed once.

        Normals need a KD-tree of the whole cloud (built when a point's class is first asked
        for, and kept as the job's memory budget allows) but are computed only for the points
        asked for: the ones the camera sees.
        """
        from nbcalib.registration.orientation import class_of_normals, point_normals

        cloud = self.cloud
        n = len(cloud)
        if cloud.classes is None or len(cloud.classes) != n:
            cloud.classes = np.full(n, -1, dtype=np.int8)
        classes = cloud.classes
        idx = np.arange(n) if indices is None else np.asarray(indices, dtype=np.int64)
        missing = idx[classes[idx] < 0]
        if missing.size:
            pts = np.asarray(self.points_lidar, dtype=np.float64)
            tree = cloud.memo("tree", lambda: _Tree(pts))
            ok = np.isin(missing, tree.finite) if tree.tree is not None else missing < -1
            classes[missing[~ok]] = 0
            if ok.any():
                normals = point_normals(
                    pts[tree.finite],
                    indices=np.searchsorted(tree.finite, missing[ok]),
                    tree=tree.tree,
                )
                classes[missing[ok]] = class_of_normals(normals)
        return classes[idx]


def visible_subset(
    pair: RegistrationPair, T_camera_lidar, config: RefineConfig, select=None
) -> np.ndarray:
    """Indices of the pair's points that the camera sees from ``T_camera_lidar``.

    ``select`` (optional) takes them in cloud order and returns the ones to keep, before they
    are sorted by pixel (:func:`~nbcalib.preprocess.lidar_image.visible_indices`).
    """
    if not config.hidden_point_removal:
        _, valid = pair.camera.project(
            pair.points_lidar @ T_camera_lidar[:3, :3].T + T_camera_lidar[:3, 3], in_image=True
        )
        keep = np.flatnonzero(valid)
        return keep if select is None else select(keep)
    # sorted by pixel: the cost then reads the image in order (1.3-2.6x cheaper evaluations)
    keep, pixel = pair.visibility(T_camera_lidar, config.depth_margin, config.window)
    if select is not None:  # a subset of keep, in its order: their pixels by position
        chosen = select(keep)
        pixel, keep = pixel[np.searchsorted(keep, chosen)], chosen
    return keep[np.argsort(pixel, kind="stable")].astype(np.int64)


def downscale_camera(camera: CameraModel, level: int) -> CameraModel:
    """The camera of an image averaged over ``2^level x 2^level`` pixel blocks.

    Coarse pixel ``i`` averages fine pixels ``2i`` and ``2i + 1``, so its centre is the fine
    position ``2i + 0.5`` (pixel centres at integers, docs/conventions.md):
    ``u_coarse = (u_fine + 0.5) / 2 - 0.5``, which every model meets by scaling ``fx, fy`` (or the
    equirectangular ``W, H``) by 1/2 and mapping ``cx, cy`` like ``u``. The image size is rounded
    down (the last odd row or column is dropped).
    """
    if level == 0:
        return camera
    f = 2**level
    intr = np.array(camera.intrinsics, dtype=np.float64)
    if camera.model == "equirectangular":
        intr[:2] = camera.width // f, camera.height // f
    else:
        intr[:2] /= f
        intr[2:4] = (intr[2:4] + 0.5) / f - 0.5
    return create_camera(
        camera.model, intr, camera.distortion_coeffs, camera.width // f, camera.height // f
    )


def downscale_image(image, level: int, *, equalize: bool = True) -> np.ndarray:
    """Grey image averaged over ``2^level`` blocks and histogram-equalised again (uint8).

    ``equalize=False`` keeps the block means (rounded to uint8): for edge images, whose
    equalisation would lift flat regions' noise (:mod:`nbcalib.registration.structure`).

    Parameters
    ----------
    image : ndarray of shape (H, W), uint8, uint16 or float in [0, 1]

    Returns
    -------
    ndarray of shape (H // 2^level, W // 2^level), uint8 (level 0: the image unchanged)
    """
    if level == 0:
        return image
    from nbcalib.preprocess.intensity import equalize_image

    img = np.asarray(image)
    scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype, 1.0)
    img = img.astype(np.float64) / scale
    f = 2**level
    h, w = img.shape[0] // f, img.shape[1] // f
    blocks = img[: h * f, : w * f].reshape(h, f, w, f).mean(axis=(1, 3))
    if not equalize:
        return np.round(blocks * 255.0).astype(np.uint8)
    return equalize_image(blocks)
