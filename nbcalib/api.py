"""Calibrate from arrays or files in a few lines: :func:`calibrate`.

>>> import nbcalib
>>> result = nbcalib.calibrate(points, intensities, image, "camera.yaml")   # doctest: +SKIP
>>> result.T_lidar_camera            # p_lidar = T_lidar_camera @ p_camera  # doctest: +SKIP
>>> result.pairs[0].lidar_image      # the intermediate products            # doctest: +SKIP

The steps are the command line's (``nbcalib run``), in memory: the stages' public functions
(:func:`nbcalib.preprocess.pipeline.preprocess`, :func:`nbcalib.matching.match_images`,
:func:`nbcalib.initial_guess.estimate.estimate_initial_guess`,
:func:`nbcalib.registration.refine.refine`), with a work directory that is temporary unless
``workdir`` is given (then ``calib.json`` there receives the results, and the CLI can continue).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from nbcalib.errors import InputError

__all__ = ["CalibrationResult", "PairProducts", "calibrate"]


@dataclass
class PairProducts:
    """What the pipeline made of one LiDAR-camera pair.

    Attributes
    ----------
    name : str
        Data name (``000000``, ``000001``, ...).
    image : ndarray of shape (H, W), uint8
        The camera image as used (grey, equalised unless switched off).
    points_lidar : ndarray of shape (N, 3), float64
        The dense cloud, LiDAR frame, metres.
    intensities : ndarray of shape (N,), float64
        Its equalised intensities in [0, 1).
    lidar_image : ndarray of shape (H', W'), uint8
        The LiDAR intensity image of the virtual camera.
    lidar_index : ndarray of shape (H', W'), int32
        Row of ``points_lidar`` shown by each LiDAR-image pixel, -1 where empty.
    matches : Matches or None
        Keypoint matches between ``image`` and ``lidar_image`` (None with ``T_init``).
    correspondences : Correspondences or None
        The matches lifted to 2D-3D correspondences.
    """

    name: str
    image: np.ndarray
    points_lidar: np.ndarray
    intensities: np.ndarray
    lidar_image: np.ndarray
    lidar_index: np.ndarray
    matches: Any = None
    correspondences: Any = None


@dataclass
class CalibrationResult:
    """The extrinsic, how it was found, and how far to trust it.

    Attributes
    ----------
    T_camera_lidar : ndarray of shape (4, 4), float64
        ``p_camera = T_camera_lidar @ p_lidar``: the result of fine registration.
    T_init : ndarray of shape (4, 4), float64
        Where fine registration started (``T_camera_lidar`` form).
    init_source : str
        ``"T_init"`` (given) or the matcher whose matches gave the automatic guess.
    initial_guess : InitialGuess or None
        The automatic guess (:mod:`nbcalib.initial_guess`), None when ``T_init`` was given.
    pairs : list of PairProducts
        Intermediate products per pair.
    refinement : RefineResult
        Fine registration: ``history`` holds the NID of each outer iteration.
    quality : object or None
        :func:`nbcalib.report.assess`'s figures (uncertainty, verdict) when that module is
        installed, else None.
    camera : CameraModel
        The camera.
    workdir : pathlib.Path or None
        The work directory kept (``workdir`` argument), else None.
    """

    T_camera_lidar: np.ndarray
    T_init: np.ndarray
    init_source: str
    initial_guess: Any
    pairs: list[PairProducts]
    refinement: Any
    camera: Any
    quality: Any = None
    workdir: Path | None = None
    extra: dict = field(default_factory=dict)

    @property
    def T_lidar_camera(self) -> np.ndarray:
        """``p_lidar = T_lidar_camera @ p_camera`` (the ``calib.json`` direction), (4, 4)."""
        from nbcalib.transforms import invert_T

        return invert_T(self.T_camera_lidar)

    @property
    def nid_history(self) -> list[float]:
        """NID at the start, then after each outer iteration of fine registration."""
        history = self.refinement.history
        return [history[0].nid_start, *(step.nid for step in history)] if history else []

    @property
    def xyz_quat(self) -> list[float]:
        """``T_lidar_camera`` as ``[x, y, z, qx, qy, qz, qw]`` (``calib.json``'s layout)."""
        from nbcalib.transforms import pose_to_xyz_quat

        return [float(v) for v in pose_to_xyz_quat(self.T_lidar_camera)]

    def __repr__(self) -> str:
        values = ", ".join(f"{v:.4f}" for v in self.xyz_quat)
        nid = self.nid_history
        return (
            f"CalibrationResult(T_lidar_camera=[{values}] (x y z qx qy qz qw), "
            f"{len(self.pairs)} pair(s), start: {self.init_source}, "
            f"NID {nid[0]:.4f} -> {nid[-1]:.4f})"
        )


def _as_list(value, what: str) -> list:
    """One pair's input, or a list/tuple of them (one per pair)."""
    if isinstance(value, (list, tuple)):
        if not value:
            raise ValueError(f"{what}: empty list")
        return list(value)
    return [value]


def _load_cloud(points, intensities):
    """A :class:`~nbcalib.io.pointcloud.PointCloud` from a file or from arrays."""
    from nbcalib.io.pointcloud import PointCloud, read_pointcloud

    if isinstance(points, (str, os.PathLike)):
        cloud = read_pointcloud(points)
        if intensities is not None:
            cloud = PointCloud(cloud.points, _intensities(intensities, len(cloud)), cloud.times)
        return cloud
    xyz = np.ascontiguousarray(points, dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] not in (3, 4):
        raise ValueError(f"points must have shape (N, 3) or (N, 4), got {xyz.shape}")
    if intensities is None:
        if xyz.shape[1] != 4:
            raise ValueError("give intensities, or points of shape (N, 4) with intensity last")
        intensities = xyz[:, 3]
    values = _intensities(intensities, len(xyz))
    keep = np.all(np.isfinite(xyz[:, :3]), axis=1) & np.isfinite(values)
    return PointCloud(np.ascontiguousarray(xyz[keep, :3]), values[keep])


def _intensities(values, n: int) -> np.ndarray:
    values = np.ascontiguousarray(values, dtype=np.float64).reshape(-1)
    if values.shape != (n,):
        raise ValueError(f"intensities must have shape ({n},), got {values.shape}")
    return values


def _load_image(image) -> np.ndarray:
    from nbcalib.io.image import read_image

    if isinstance(image, (str, os.PathLike)):
        if not Path(image).is_file():
            raise InputError("image not found", image)
        return read_image(image, grey=True)
    array = np.asarray(image)
    if array.ndim == 3 and array.shape[2] in (3, 4):  # RGB(A) -> grey (ITU-R BT.601)
        array = array[..., :3].astype(np.float64) @ np.array([0.299, 0.587, 0.114])
        array = np.round(array).astype(np.uint8) if np.asarray(image).dtype == np.uint8 else array
    if array.ndim != 2:
        raise ValueError(f"image must have shape (H, W) or (H, W, 3), got {array.shape}")
    if array.dtype != np.uint8:
        array = np.asarray(array, dtype=np.float64)
        if not np.all(np.isfinite(array)):
            raise ValueError("image holds non-finite values")
        if array.max(initial=0.0) > 1.0:
            raise ValueError("a float image must be in [0, 1] (or pass uint8)")
        array = np.round(array * 255.0).astype(np.uint8)
    return array


def _load_camera(camera, image_shape):
    from nbcalib.camera import CameraModel
    from nbcalib.io.camera_file import load_camera

    if isinstance(camera, CameraModel):
        return camera
    if isinstance(camera, (str, os.PathLike)):
        height, width = image_shape[:2]
        return load_camera(camera, width=width, height=height)
    raise TypeError(f"camera must be a CameraModel or a camera file path, got {type(camera)}")


def calibrate(
    points,
    intensities,
    image,
    camera,
    *,
    T_init=None,
    workdir: str | os.PathLike | None = None,
    matcher: str = "auto",
    model_dir: str | os.PathLike | None = None,
    voxel_size: float = 0.002,
    min_distance: float = 1.0,
    equalize: bool = True,
    ransac_iterations: int = 8192,
    ransac_threshold: float = 5.0,
    seed: int = 0,
    optimizer: str = "hybrid",
    bins: int = 16,
    max_outer: int = 10,
    log: Callable[[str], None] | None = None,
) -> CalibrationResult:
    """Calibrate a LiDAR-camera pair (or several) from arrays or files.

    Parameters
    ----------
    points : ndarray of shape (N, 3) or (N, 4), float, or str, or a list of them
        Point cloud in the LiDAR frame, metres (a dense cloud or one scan; a LiDAR at rest),
        or a point cloud file (``.pcd``, ``.ply``, ``.bin``, ``.npy``, ``.npz``). A list gives
        several pairs, which share the extrinsic.
    intensities : ndarray of shape (N,), float, or None, or a list of them
        LiDAR intensities, any scale (rank-equalised here); None when ``points`` is a file or
        has intensity as its fourth column.
    image : ndarray of shape (H, W) or (H, W, 3), uint8 or float in [0, 1], or str, or a list
        The camera image (or its file).
    camera : CameraModel or str
        The camera, or a camera file (ROS camera_info YAML, OpenCV/nbcalib YAML/JSON,
        ``calib.json``).
    T_init : array_like of shape (4, 4), optional
        Start of fine registration, ``p_camera = T_init @ p_lidar``; default: the automatic
        guess from keypoint matches.
    workdir : str or os.PathLike, optional
        Keep the work directory here (``calib.json`` gets the results); default: temporary.
    matcher : str, optional
        ``auto`` (best installed), a learned matcher, or ``sift``.
    model_dir : str or os.PathLike, optional
        Exported matcher models (default: ``$NBCALIB_MODEL_DIR`` or the user cache).
    voxel_size, min_distance : float, optional
        Dense cloud voxel and nearest range kept, metres.
    equalize : bool, optional
        Equalise LiDAR intensities and the camera image (paper III-C).
    ransac_iterations, ransac_threshold, seed : optional
        Initial guess: RANSAC hypotheses, inlier threshold (pixels), seed.
    optimizer : {"hybrid", "lbfgs", "nelder_mead"}, optional
        Fine registration's optimiser (:class:`~nbcalib.registration.config.RefineConfig`).
    bins : int, optional
        NID histogram bins.
    max_outer : int, optional
        Outer iterations of fine registration at most.
    log : callable, optional
        Receives progress lines (default: silent).

    Returns
    -------
    CalibrationResult

    Raises
    ------
    InputError
        A missing or corrupt file, or an automatic guess without enough inliers (pass
        ``T_init`` then).
    """
    from nbcalib.preprocess.pipeline import PairInput, PreprocessConfig, preprocess

    log = log or (lambda line: None)
    clouds = _as_list(points, "points")
    values = _as_list(intensities, "intensities") if intensities is not None else [None]
    images = _as_list(image, "image")
    if len(values) == 1 and len(clouds) > 1 and values[0] is None:
        values = values * len(clouds)
    if not len(clouds) == len(values) == len(images):
        raise ValueError(
            f"one image and one intensity array per cloud: got {len(clouds)} clouds, "
            f"{len(values)} intensity arrays, {len(images)} images"
        )
    grey = [_load_image(im) for im in images]
    cam = _load_camera(camera, grey[0].shape)
    pairs = [
        PairInput(f"{k:06d}", [_load_cloud(c, v)], g, f"image {k}")
        for k, (c, v, g) in enumerate(zip(clouds, values, grey))
    ]
    config = PreprocessConfig(
        mode="static",
        voxel_size=voxel_size,
        min_distance=min_distance,
        equalize_intensities=equalize,
        equalize_image=equalize,
    )
    with _work_directory(workdir) as path:
        preprocess(pairs, path, camera=cam, config=config, log=log)
        products = _load_products(path)
        guess, init_source = None, "T_init"
        if T_init is None:
            guess, init_source = _initial_guess(
                path, cam, products, matcher, model_dir, ransac_iterations, ransac_threshold, seed
            )
            T_start = guess.T_camera_lidar
        else:
            from nbcalib.transforms import validate_T

            T_start = validate_T(np.asarray(T_init, dtype=np.float64), "T_init")
        refinement, quality = _refine(cam, products, T_start, optimizer, bins, max_outer, log)
        result = CalibrationResult(
            T_camera_lidar=refinement.T_camera_lidar,
            T_init=np.array(T_start, dtype=np.float64),
            init_source=init_source,
            initial_guess=guess,
            pairs=products,
            refinement=refinement,
            camera=cam,
            quality=quality,
            workdir=None if workdir is None else Path(workdir),
        )
        if workdir is not None:
            _write_results(path, result)
    return result


class _work_directory:
    """The given work directory, or a temporary one removed afterwards."""

    def __init__(self, workdir):
        self.workdir = workdir
        self.tmp = None

    def __enter__(self) -> Path:
        if self.workdir is not None:
            return Path(self.workdir)
        self.tmp = tempfile.TemporaryDirectory(prefix="nbcalib_")
        return Path(self.tmp.name)

    def __exit__(self, *exc) -> None:
        if self.tmp is not None:
            self.tmp.cleanup()


def _load_products(path: Path) -> list[PairProducts]:
    from nbcalib.workdir import WorkDir

    work = WorkDir(path)
    products = []
    for name in work.names():
        p = work.load_pair(name)
        products.append(
            PairProducts(
                p.name, p.image, p.points_lidar, p.intensities, p.lidar_intensity, p.lidar_index
            )
        )
    return products


def _initial_guess(path, camera, products, matcher, model_dir, iterations, threshold, seed):
    from nbcalib.initial_guess.correspondences import (
        correspondences_from_matches,
        pool_correspondences,
    )
    from nbcalib.initial_guess.estimate import MIN_CORRESPONDENCES, estimate_initial_guess
    from nbcalib.matching.match import camera_scale_for, match_images, resolve_matcher
    from nbcalib.workdir import WorkDir, get_virtual_camera

    name = resolve_matcher(matcher, model_dir)
    virtual = get_virtual_camera(WorkDir(path).read_calib())
    scale = camera_scale_for(camera, virtual[0]) if virtual is not None else None
    parts = []
    for pair in products:
        pair.matches = match_images(
            pair.image, pair.lidar_image, matcher=name, camera_scale=scale, model_dir=model_dir
        )
        pair.correspondences = correspondences_from_matches(
            pair.matches, pair.lidar_index, pair.points_lidar, name=pair.name
        )
        parts.append(pair.correspondences)
    corr = pool_correspondences(parts)
    if len(corr) < MIN_CORRESPONDENCES:
        raise InputError(
            f"automatic initial guess: only {len(corr)} correspondences from {name}; "
            "pass T_init (or export a learned matcher: nbcalib models export)"
        )
    guess = estimate_initial_guess(
        camera,
        corr.uv_camera,
        corr.points_lidar,
        ransac_iterations=iterations,
        ransac_threshold=threshold,
        seed=seed,
        weights=corr.weights,
    )
    if not guess.success:
        raise InputError(
            f"automatic initial guess failed ({guess.summary()}); pass T_init "
            "(or export a learned matcher: nbcalib models export)"
        )
    return guess, name


def _refine(camera, products, T_start, optimizer, bins, max_outer, log):
    from nbcalib.registration.refine import RefineConfig, RegistrationPair, refine

    try:
        config = RefineConfig(optimizer=optimizer, bins=bins, max_outer=max_outer)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    pairs = [
        RegistrationPair(camera, p.image, p.points_lidar, p.intensities, p.name) for p in products
    ]

    def progress(i, step):
        log(f"outer {i + 1}: NID {step.nid_start:.5f} -> {step.nid:.5f}")

    result = refine(pairs, T_start, config, progress=progress)
    quality = None
    if _has_report():
        from nbcalib.report import assess

        quality = assess(
            pairs, result.T_camera_lidar, T_init=T_start, config=config, converged=result.converged
        )
    return result, quality


def _has_report() -> bool:
    import importlib.util

    return importlib.util.find_spec("nbcalib.report") is not None


def _write_results(path: Path, result: CalibrationResult) -> None:
    from nbcalib.io.calib_json import AUTO_STAGE, FINAL_STAGE
    from nbcalib.workdir import WorkDir

    work = WorkDir(path)
    calib = work.read_calib()
    if result.initial_guess is not None:
        calib.set_T_camera_lidar(AUTO_STAGE, result.initial_guess.T_camera_lidar)
    calib.set_T_camera_lidar(FINAL_STAGE, result.T_camera_lidar)
    calib.nbcalib["calibration"] = {
        "start": result.init_source,
        "nid_history": result.nid_history,
        "converged": bool(result.refinement.converged),
    }
    work.write_calib(calib)
