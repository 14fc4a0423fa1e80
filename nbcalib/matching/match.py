"""Match a camera image with a LiDAR intensity image (paper section III-D, first step).

:func:`match_images` prepares both images (rotation, hole filling, normalisation), runs a
learned matcher through onnxruntime, or the SIFT fallback, and returns keypoints in the
original, unrotated pixel coordinates of both images.

Differences from the reference's ``find_matches_superglue.py``:

- SuperGlue is replaced by permissively licensed models (:mod:`nbcalib.matching.onnx_export`).
- Rotated keypoints are mapped back exactly: a keypoint at column ``u'`` of an image rotated
  by 180 degrees is at ``W - 1 - u'`` (the reference uses ``W - u'``, one pixel off).
- The images are normalised before matching (:mod:`nbcalib.matching.normalize`).
"""

from __future__ import annotations

import functools
import logging
import os
import time
from dataclasses import replace

import numpy as np

from nbcalib.matching.config import LEARNED_MATCHER_NAMES, ROTATIONS, MatchConfig
from nbcalib.matching.matches import Matches
from nbcalib.matching.onnx_matcher import OnnxMatcher, exported_matchers
from nbcalib.matching.onnx_matcher import model_dir as _model_dir

__all__ = [
    "MATCHERS",
    "available_matchers",
    "camera_scale_for",
    "match_images",
    "mutual_nearest",
    "pixels_per_radian",
    "resolve_matcher",
    "rotate_image",
    "unrotate_points",
]

log = logging.getLogger(__name__)

#: Every matcher name ``match_images`` accepts (besides ``auto``), best first.
MATCHERS = (*LEARNED_MATCHER_NAMES, "sift")


def available_matchers(directory: str | os.PathLike | None = None) -> list[str]:
    """Matchers that can run here, best first: exported learned matchers, then ``sift``.

    Parameters
    ----------
    directory : str or os.PathLike, optional
        Model directory (default: :func:`~nbcalib.matching.onnx_matcher.model_dir`).
    """
    learned = []
    try:
        import onnxruntime  # noqa: F401

        learned = exported_matchers(directory)
    except ImportError:
        pass
    return [*learned, "sift"]


def resolve_matcher(matcher: str, directory: str | os.PathLike | None = None) -> str:
    """The matcher ``auto`` stands for (the best available), or ``matcher`` itself if known."""
    if matcher == "auto":
        best = available_matchers(directory)[0]
        if best == "sift":
            log.warning(
                "no learned matcher exported in %s: using the SIFT fallback (fewer correct "
                "matches); run 'nbcalib models export' to make one",
                _model_dir(directory),
            )
        return best
    if matcher not in MATCHERS:
        raise ValueError(f"unknown matcher {matcher!r}; one of {['auto', *MATCHERS]}")
    return matcher


def _check_rotation(degrees: int, name: str) -> int:
    if degrees not in ROTATIONS:
        raise ValueError(f"{name} must be one of {ROTATIONS} (clockwise degrees), got {degrees}")
    return int(degrees)


def rotate_image(image: np.ndarray, degrees: int) -> np.ndarray:
    """Rotate an image clockwise by 0, 90, 180 or 270 degrees (lossless).

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, C)
    degrees : int
        Clockwise rotation.

    Returns
    -------
    ndarray
        (H, W) for 0 and 180 degrees, (W, H) for 90 and 270.
    """
    degrees = _check_rotation(degrees, "degrees")
    # clockwise by 90 k = counter-clockwise np.rot90 by -k
    return np.ascontiguousarray(np.rot90(image, k=-degrees // 90))


def unrotate_points(points: np.ndarray, degrees: int, size: tuple[int, int]) -> np.ndarray:
    """Map pixels of an image rotated by :func:`rotate_image` back to the original image.

    Pixel centres are at integers, so the exact inverse uses ``W - 1 - u`` (not ``W - u``).

    Parameters
    ----------
    points : ndarray of shape (N, 2)
        ``(u', v')`` in the rotated image, pixels.
    degrees : int
        The clockwise rotation that was applied.
    size : tuple of int
        ``(W, H)`` of the original image.

    Returns
    -------
    ndarray of shape (N, 2), float64
        ``(u, v)`` in the original image.
    """
    degrees = _check_rotation(degrees, "degrees")
    p = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    width, height = size
    u, v = p[:, 0], p[:, 1]
    if degrees == 0:
        out = (u, v)
    elif degrees == 90:  # rotated (u', v') shows original (v', H - 1 - u')
        out = (v, height - 1 - u)
    elif degrees == 180:
        out = (width - 1 - u, height - 1 - v)
    else:  # 270: rotated (u', v') shows original (W - 1 - v', u')
        out = (width - 1 - v, u)
    return np.column_stack(out)


@functools.lru_cache(maxsize=4)
def _session(name: str, directory: str, threads: int | None) -> OnnxMatcher:
    return OnnxMatcher(name, directory, threads=threads)


def _threads(threads: int | None) -> int:
    """ONNX Runtime's intra-op threads: ``threads``, else the cores (fewer during a warm-up).

    One core fewer while a first run's warm-up compiles (:func:`nbcalib.warmup.running`). Two
    threads racing the warm-up for two cores waited on each other: a cold demo's matching took
    30-32 s against 16.5 s warm; with one thread 21-23 s (19-20 s warm), and the warm-up
    compiles on the other core (docs/BENCHMARKS.md 7).
    """
    if threads is not None:
        return threads
    from nbcalib import warmup

    cores = os.cpu_count() or 1
    return max(1, cores - 1) if warmup.running() else cores


def pixels_per_radian(camera) -> float:
    """Angular resolution of a camera at its image centre, pixels per radian.

    The mean of the angles between the bearings of the centre pixel and of its right and lower
    neighbours (any camera model, through ``camera.unproject``).
    """
    cu, cv = (camera.width - 1) / 2.0, (camera.height - 1) / 2.0
    bearings = camera.unproject(np.array([[cu, cv], [cu + 1.0, cv], [cu, cv + 1.0]]))
    dots = np.clip(bearings[1:] @ bearings[0], -1.0, 1.0)
    return float(1.0 / np.mean(np.arccos(dots)))


def camera_scale_for(camera, lidar_camera) -> float:
    """The ``camera_scale`` of :func:`match_images` that gives both images the same resolution.

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    lidar_camera : CameraModel
        The virtual camera that rendered the LiDAR image.

    Returns
    -------
    float
        ``pixels_per_radian(lidar_camera) / pixels_per_radian(camera)``.
    """
    return pixels_per_radian(lidar_camera) / pixels_per_radian(camera)


def _check_grey(image, name):
    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(
            f"{name} must be a (H, W) uint8 grey image, got {image.dtype} {image.shape}"
        )
    return image


def _resize(image: np.ndarray, factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Resize by ``factor``; returns the image and the per-axis scale actually applied (u, v)."""
    import cv2

    height, width = image.shape
    w, h = max(round(width * factor), 1), max(round(height * factor), 1)
    if (w, h) == (width, height):
        return image, np.ones(2)
    interpolation = cv2.INTER_AREA if factor < 1.0 else cv2.INTER_LINEAR
    return cv2.resize(image, (w, h), interpolation=interpolation), np.array([w / width, h / height])


def mutual_nearest(descriptors0: np.ndarray, descriptors1: np.ndarray):
    """Mutual nearest neighbours of two sets of unit descriptors (cosine similarity).

    The cheap matcher of the heading sweep's screen (:func:`match_images` with ``screen``):
    one matrix product instead of LightGlue's attention layers.

    Parameters
    ----------
    descriptors0 : ndarray of shape (M, D)
    descriptors1 : ndarray of shape (N, D)
        L2-normalised descriptors (as the learned extractors return them).

    Returns
    -------
    matches0 : ndarray of shape (M,), int64
        Index into the second set, -1 when not mutual.
    scores0 : ndarray of shape (M,), float64
        The cosine similarity of each mutual pair, else 0.
    """
    d0 = np.asarray(descriptors0, dtype=np.float32)
    d1 = np.asarray(descriptors1, dtype=np.float32)
    m = len(d0)
    if m == 0 or len(d1) == 0:
        return np.full(m, -1, dtype=np.int64), np.zeros(m)
    similarity = d0 @ d1.T
    best0 = np.argmax(similarity, axis=1)
    best1 = np.argmax(similarity, axis=0)
    mutual = best1[best0] == np.arange(m)
    scores0 = np.where(mutual, similarity[np.arange(m), best0], 0.0).astype(np.float64)
    return np.where(mutual, best0, -1).astype(np.int64), scores0


def match_images(
    camera_image: np.ndarray,
    lidar_image: np.ndarray,
    config: MatchConfig | None = None,
    *,
    camera_scale: float | None = None,
    lidar_fill_radius: int | None = None,
    model_dir: str | os.PathLike | None = None,
    screen: bool = False,
    cache: dict | None = None,
    **overrides,
) -> Matches:
    """Match keypoints between a camera image and a LiDAR intensity image.

    Steps: fill the LiDAR image's holes, rotate both images, resample the camera image by
    ``camera_scale`` (so that both images have the same pixels per degree, which the matchers
    need: they are not invariant to a scale change of 2 or more), shrink both by one common
    factor so that no side exceeds ``max_image_side``, normalise, extract and match; the
    keypoints are mapped back to the original images.

    Parameters
    ----------
    camera_image : ndarray of shape (H, W), uint8
        The camera image (grey).
    lidar_image : ndarray of shape (h, w), uint8
        The LiDAR intensity image (0 = empty pixel).
    config : MatchConfig, optional
        Matcher, thresholds, rotations, normalisations, image and keypoint limits (documented
        there); default ``MatchConfig()``.
    camera_scale : float, optional
        Resample the camera image by this factor (:func:`camera_scale_for` computes it from the
        two cameras); default ``config.camera_scale``, else 1.
    lidar_fill_radius : int, optional
        Fill empty LiDAR pixels from filled ones this close before normalising (pixels, 0 =
        off); default ``config.fill_radius``.
    model_dir : str or os.PathLike, optional
        Where the exported models are (default: ``$NBCALIB_MODEL_DIR`` or the user cache).
    screen : bool, optional
        A learned matcher's keypoints matched by their descriptors' mutual nearest neighbours
        (:func:`mutual_nearest`, confidence = cosine similarity) instead of by the matcher: a
        tenth of the time, fewer and noisier matches; how the heading sweep ranks its views
        (:mod:`nbcalib.matching.multiview`). SIFT ignores it.
    cache : dict, optional
        The camera image's features are kept here and taken from here by later calls with the
        same camera image (the caller's promise) and the same settings: the heading sweep
        extracts them once, not once per view.
    **overrides
        Attributes of :class:`MatchConfig` to change for this call (``matcher="sift"``, ...).

    Returns
    -------
    Matches
        ``kpts_camera`` (M, 2), ``kpts_lidar`` (K, 2), ``matches`` (M,), ``confidence`` (M,);
        ``matcher`` names the matcher used and ``info`` the options and timings.

    Raises
    ------
    InputError
        A learned matcher was asked for by name but has not been exported (the message names
        the command that exports it).
    """
    cfg = replace(config or MatchConfig(), **overrides)
    if camera_scale is None:
        camera_scale = cfg.camera_scale
    if lidar_fill_radius is None:
        lidar_fill_radius = cfg.fill_radius
    match_threshold, max_image_side = cfg.match_threshold, cfg.max_image_side
    rotate_camera, rotate_lidar = cfg.rotate_camera, cfg.rotate_lidar
    camera_normalization, lidar_normalization = cfg.camera_normalization, cfg.lidar_normalization
    max_keypoints = cfg.max_keypoints
    from nbcalib.matching.normalize import fill_holes, normalize_image

    camera_image = _check_grey(camera_image, "camera_image")
    lidar_image = _check_grey(lidar_image, "lidar_image")
    scale = 1.0 if camera_scale is None else float(camera_scale)
    if not (np.isfinite(scale) and 0.05 <= scale <= 20.0):
        raise ValueError(f"camera_scale must be in [0.05, 20], got {camera_scale}")
    name = resolve_matcher(cfg.matcher, model_dir)
    t0 = time.perf_counter()
    lidar = fill_holes(lidar_image, radius=lidar_fill_radius) if lidar_fill_radius else lidar_image
    cam = rotate_image(camera_image, rotate_camera)
    lid = rotate_image(lidar, rotate_lidar)
    longest = max(max(cam.shape) * scale, max(lid.shape))
    common = min(1.0, max_image_side / longest) if max_image_side else 1.0
    lid, lid_factor = _resize(lid, common)
    lid = normalize_image(lid, lidar_normalization)
    # the camera image's part depends on these alone (the LiDAR image only through its size)
    camera_key = (
        name,
        rotate_camera,
        scale * common,
        camera_normalization,
        max_keypoints,
        cfg.detection_threshold,
    )
    cached = None if cache is None else cache.get(camera_key)
    if cached is None:
        cam, cam_factor = _resize(cam, scale * common)
        cam = normalize_image(cam, camera_normalization)
    else:
        cam, cam_factor, f0 = cached
    screened = screen and name != "sift"
    if name == "sift":
        from nbcalib.matching.sift import sift_features, sift_match

        if cached is None:
            f0 = sift_features(cam, max_keypoints=max_keypoints or 0)
        kpts0, desc0 = f0
        kpts1, desc1 = sift_features(lid, max_keypoints=max_keypoints or 0)
        matches0, confidence = sift_match(desc0, desc1, ratio=cfg.sift_ratio)
    else:
        session = _session(name, str(_model_dir(model_dir)), _threads(cfg.threads))
        options = dict(
            detection_threshold=cfg.detection_threshold, max_keypoints=max_keypoints, resize=None
        )
        if cached is None:
            f0 = session.extract(cam, **options)
        f1 = session.extract(lid, **options)
        if screened:
            matches0, confidence = mutual_nearest(f0.descriptors, f1.descriptors)
        else:
            matches0, confidence = session.match(f0, f1, match_threshold=match_threshold)
        kpts0, kpts1 = f0.keypoints, f1.keypoints
    if cache is not None and cached is None:
        cache[camera_key] = (cam, cam_factor, f0)
    # resized -> rotated originals (centres at integers) -> originals
    kpts0 = (kpts0 + 0.5) / cam_factor - 0.5
    kpts1 = (kpts1 + 0.5) / lid_factor - 0.5
    h0, w0 = camera_image.shape
    h1, w1 = lidar_image.shape
    info = {
        "match_threshold": float(match_threshold),
        "rotate_camera": rotate_camera,
        "rotate_lidar": rotate_lidar,
        "camera_scale": scale,
        "max_image_side": max_image_side,
        "camera_normalization": camera_normalization,
        "lidar_normalization": lidar_normalization,
        "lidar_fill_radius": int(lidar_fill_radius),
        "max_keypoints": max_keypoints,
        "screen": screened,
        "seconds": round(time.perf_counter() - t0, 3),
    }
    return Matches(
        unrotate_points(kpts0, rotate_camera, (w0, h0)),
        unrotate_points(kpts1, rotate_lidar, (w1, h1)),
        matches0,
        confidence,
        matcher=name,
        info=info,
    )
