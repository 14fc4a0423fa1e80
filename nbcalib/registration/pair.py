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
from nbcalib.registration.config import RefineConfig

__all__ = ["RegistrationPair", "downscale_camera", "downscale_image", "visible_subset"]


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
    classes : ndarray of shape (N,), int8, optional
        Surface-orientation class of each point
        (:func:`~nbcalib.registration.orientation.orientation_classes`), -1 where not known
        yet; computed for the visible points on first use when None.
    T_camera_rig : ndarray of shape (4, 4), optional
        For a pair of another camera of a rig: this camera from the rig's reference camera,
        whose ``T_camera_lidar`` is refined (the pair is seen at ``T_camera_rig @ T``). None:
        the pair's camera is the one refined.
    """

    camera: CameraModel
    image: np.ndarray
    points_lidar: np.ndarray
    intensities: np.ndarray
    name: str = ""
    classes: np.ndarray | None = field(default=None, repr=False)
    T_camera_rig: np.ndarray | None = field(default=None, repr=False, compare=False)
    _edges: tuple | None = field(default=None, repr=False, compare=False)
    _tree: object = field(default=None, repr=False, compare=False)
    _finite: np.ndarray | None = field(default=None, repr=False, compare=False)
    _cache_key: tuple | None = field(default=None, repr=False, compare=False)
    _keys: np.ndarray | None = field(default=None, repr=False, compare=False)
    _visible: tuple | None = field(default=None, repr=False, compare=False)

    def visibility(self, T_camera_lidar, margin: float, window: int):
        """:func:`~nbcalib.preprocess.lidar_image.visibility` at one pose, kept for later calls.

        The report asks for the visible set at the result four times (its cost, the pixels
        covered, the overlays) and at the start once: the z-buffer is computed once per pose
        for the last two poses asked.
        """
        from nbcalib.preprocess.lidar_image import visibility

        T = np.asarray(T_camera_lidar, dtype=np.float64)
        key = (T.tobytes(), float(margin), int(window))
        memo = [
            m
            for m in (self._visible or ())
            # the camera and the cloud themselves, not their ids (an id is reused once freed)
            if m[1] is self.camera and m[2] is self.points_lidar
        ]
        for m in memo:
            if m[0] == key:
                return m[3], m[4]
        found = visibility(self.camera, T, self.points_lidar, margin=margin, window=window)
        entry = (key, self.camera, self.points_lidar, *found)
        self._visible = (entry, *memo[:1])
        return entry[3], entry[4]

    def structure(self) -> tuple[np.ndarray, np.ndarray]:
        """(depth-edge score per point, image edge strength): the structure channel, made once.

        :mod:`nbcalib.registration.structure`; both depend on the data only, not on the pose.
        """
        from nbcalib.registration.structure import depth_edge_scores, image_edges

        key = (id(self.points_lidar), id(self.image))
        if self._edges is None or self._edges[0] != key:
            self._edges = (key, depth_edge_scores(self.points_lidar), image_edges(self.image))
        return self._edges[1], self._edges[2]

    def sample(self, visible: np.ndarray, budget: float | None) -> np.ndarray:
        """About ``budget`` of the ``visible`` point indices (all of them if fewer), in order.

        A seeded random key per point (drawn once per cloud) keeps the points whose key falls
        under the needed rate, so the subset is the same for every pose and nests across
        pyramid levels; None keeps them all.
        """
        if budget is None or visible.size <= budget:
            return visible
        n = len(self.points_lidar)
        if self._keys is None or len(self._keys) != n:
            self._keys = np.random.default_rng(0).random(n, dtype=np.float32)
        return visible[self._keys[visible] < budget / visible.size]

    def orientation_classes(self, indices=None) -> np.ndarray:
        """Orientation classes of the points ``indices`` (default all), each computed once.

        Normals need a KD-tree of the whole cloud (built on first use) but are computed only
        for the points asked for: the ones the camera sees.
        """
        from nbcalib.registration.orientation import class_of_normals, point_normals

        pts = np.asarray(self.points_lidar, dtype=np.float64)
        key = (id(self.points_lidar), len(pts))
        if self._cache_key != key:
            # a new cloud (dataclasses.replace copies the fields): keep given classes only if
            # they fit it, and forget the KD-tree of the old one
            fits = self.classes is not None and len(self.classes) == len(pts)
            if not fits or self._cache_key is not None:
                self.classes = None
            self._tree = self._finite = None
            self._cache_key = key
        if self.classes is None:
            self.classes = np.full(len(pts), -1, dtype=np.int8)
        idx = np.arange(len(pts)) if indices is None else np.asarray(indices, dtype=np.int64)
        missing = idx[self.classes[idx] < 0]
        if missing.size:
            if self._tree is None:
                from nbcalib.registration.orientation import kdtree

                # non-finite points are dropped by the cost; they get class 0 and no neighbours
                self._finite = np.flatnonzero(np.isfinite(pts).all(axis=1))
                self._tree = kdtree(pts[self._finite]) if self._finite.size >= 3 else False
            ok = np.isin(missing, self._finite) if self._tree is not False else missing < -1
            self.classes[missing[~ok]] = 0
            if ok.any():
                normals = point_normals(
                    pts[self._finite],
                    indices=np.searchsorted(self._finite, missing[ok]),
                    tree=self._tree,
                )
                self.classes[missing[ok]] = class_of_normals(normals)
        return self.classes[idx]


def visible_subset(
    pair: RegistrationPair, T_camera_lidar, config: RefineConfig, select=None
) -> np.ndarray:
    """Indices of the pair's points that the camera sees from ``T_camera_lidar``.

    ``select`` (optional) takes them in cloud order and returns the ones to keep, before they
    are sorted by pixel (:func:`~nbcalib.preprocess.lidar_image.visible_indices`).
    """
    from nbcalib.preprocess.lidar_image import sorted_by_pixel

    if not config.hidden_point_removal:
        _, valid = pair.camera.project(
            pair.points_lidar @ T_camera_lidar[:3, :3].T + T_camera_lidar[:3, 3], in_image=True
        )
        keep = np.flatnonzero(valid)
        return keep if select is None else select(keep)
    # sorted by pixel: the cost then reads the image in order (1.3-2.6x cheaper evaluations)
    keep, pixel = pair.visibility(T_camera_lidar, config.depth_margin, config.window)
    return sorted_by_pixel(keep, pixel, select)


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
