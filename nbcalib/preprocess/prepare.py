"""The preprocessing and render stages: scans -> dense cloud -> LiDAR image (paper III-C, III-D).

- :func:`prepare_pair`: one pair's scans accumulated into a dense cloud, static (LiDAR at rest,
  non-repetitive scan) or dynamic (continuous-time ICP for a moving spinning LiDAR,
  :mod:`nbcalib.odometry`), in the LiDAR frame at the start of the first scan, or, for a pair
  made per image (:mod:`nbcalib.preprocess.recording`), at the image's time (the trajectory
  interpolated within the image's scan); LiDAR intensities rank-equalised and the camera image
  histogram-equalised (both optional). The cloud is kept at float32 precision, as the work
  directory's PLY stores it, so that in-memory and on-disk jobs compute the same numbers.
- :func:`render_pairs`: one virtual camera chosen from the first pair's field of view (pinhole
  under 150 degrees, else equirectangular), and every pair's LiDAR intensity image and index map
  rendered with it (z-buffer, nearest point per pixel).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import replace

import numpy as np

from nbcalib._threads import thread_map
from nbcalib.camera import CameraModel
from nbcalib.errors import InputError
from nbcalib.preprocess.config import PreprocessConfig
from nbcalib.preprocess.sources import PairInput
from nbcalib.products import PairData, VirtualCamera

__all__ = [
    "check_pairs",
    "check_scans",
    "choose_mode",
    "choose_virtual_camera",
    "describe_virtual_camera",
    "prepare_pair",
    "render_pair",
    "render_pairs",
]


def _azimuth_coverage_deg(points: np.ndarray) -> float:
    az = np.degrees(np.arctan2(points[:, 1], points[:, 0]))
    return float(np.unique(np.floor(az).astype(np.int64)).size)


def choose_mode(pair: PairInput, config: PreprocessConfig) -> str:
    """``static`` or ``dynamic`` for this pair (``config.mode``, or the ``auto`` rule)."""
    if config.mode != "auto":
        return config.mode
    if len(pair.scans) < 2:
        return "static"
    return "dynamic" if _azimuth_coverage_deg(pair.scans[0].points) > 180 else "static"


#: Images smaller than this on a side are refused (a learned matcher's cells are 8 px, and
#: fine registration's pyramid and visibility window need room around each point).
MIN_IMAGE_SIDE = 32


def check_pairs(pairs: Sequence[PairInput], camera: CameraModel) -> None:
    """Refuse inputs that cannot make a work directory (message names the pair or file).

    Checks: at least one pair, unique names, one camera for all bags, images of at least
    :data:`MIN_IMAGE_SIDE` pixels a side and of the camera's size, scans that hold points and
    intensities (:func:`check_scans`; scans read only when their pair is prepared are checked
    then, by :func:`prepare_pair`).
    """
    if not pairs:
        raise InputError("nothing to preprocess: no bag and no point cloud given")
    names = [p.name for p in pairs]
    if len(set(names)) != len(names):
        raise InputError(f"two inputs have the same name: {names}")
    first = pairs[0].camera
    for pair in pairs:
        if pair.camera is not None and first is not None and pair.camera != first:
            raise InputError(
                f"pair '{pair.name}' has another camera than '{pairs[0].name}' "
                "(mixed sensors across bags?)"
            )
        h, w = pair.image.shape[:2]
        if min(w, h) < MIN_IMAGE_SIDE:
            raise InputError(
                f"the image is {w} x {h} pixels: too small to calibrate with (keypoints and the "
                f"NID's neighbourhoods need at least {MIN_IMAGE_SIDE} x {MIN_IMAGE_SIDE})",
                path=pair.image_source,
            )
        if (w, h) != (camera.width, camera.height):
            raise InputError(
                f"the image is {w} x {h} but the camera is {camera.width} x {camera.height}",
                path=pair.image_source,
            )
        if not getattr(pair.scans, "deferred", False):  # scans read later are checked then
            check_scans(pair)


def check_scans(pair: PairInput) -> None:
    """Refuse a pair whose scans hold no point or no intensity (the message names the pair)."""
    for i, scan in enumerate(pair.scans):
        if scan.points.shape[0] == 0:
            raise InputError(f"scan {i} of pair '{pair.name}' holds no finite point")
    if all(scan.intensity is None for scan in pair.scans):
        raise InputError(
            f"the point clouds of pair '{pair.name}' have no intensity field "
            "(choose one with the intensity channel option)"
        )


def _to_uint8(image: np.ndarray) -> np.ndarray:
    if image.dtype == np.uint8:
        return image
    from nbcalib.io.image import to_float_grey

    return np.round(to_float_grey(image) * 255.0).astype(np.uint8)


def _accumulate(pair: PairInput, mode: str, config: PreprocessConfig, progress):
    from nbcalib.odometry import integrate_dynamic
    from nbcalib.preprocess.accumulate import integrate_static

    if mode == "static":
        return integrate_static(
            pair.scans,
            voxel_size=config.voxel_size,
            min_distance=config.min_distance,
            progress=progress,
        )
    return integrate_dynamic(
        pair.scans,
        config=config.odometry,
        voxel_size=config.voxel_size,
        min_distance=config.min_distance,
        frame_rate=config.frame_rate,
        progress=progress,
    )


def _shared_cloud(pair: PairInput, mode: str, config: PreprocessConfig, progress):
    """The pair's dense cloud; accumulated once for the cameras sharing ``pair.clouds``."""
    if pair.clouds is None:
        return _accumulate(pair, mode, config, progress)
    from dataclasses import asdict

    # the same scans under the same settings (the topics aside) make the same cloud
    settings = {k: v for k, v in asdict(config).items() if not k.endswith("_topic")}
    key = (mode, repr(sorted(settings.items())))
    return pair.clouds.get(key, lambda: _accumulate(pair, mode, config, progress))


def _at_image_time(cloud, scan: int, fraction: float) -> tuple[np.ndarray, float]:
    """The cloud's points in the LiDAR frame at ``fraction`` of scan ``scan``; the frame's offset.

    Returns the points and how far that frame's origin is from the first scan's start, metres.
    """
    from nbcalib.transforms import invert_T

    T_first_image = cloud.pose_at(scan, fraction)
    T_image_first = invert_T(T_first_image)
    points = cloud.points @ T_image_first[:3, :3].T + T_image_first[:3, 3]
    return points, float(np.linalg.norm(T_first_image[:3, 3]))


def prepare_pair(
    pair: PairInput,
    config: PreprocessConfig | None = None,
    *,
    log: Callable[[str], None] | None = None,
    progress: bool = True,
) -> PairData:
    """One pair's dense cloud, equalised intensities and camera image (module docstring).

    Parameters
    ----------
    pair : PairInput
        Scans and image (:meth:`nbcalib.preprocess.inputs.InputSpec.gather`, or arrays).
    config : PreprocessConfig, optional
    log : callable, optional
        Receives progress lines.
    progress : bool, optional
        A progress display of the scans integrated (more than three scans).

    Returns
    -------
    PairData
        Without a LiDAR image yet (:func:`render_pairs`).

    Raises
    ------
    InputError
        No point left after accumulation.
    """
    from nbcalib.preprocess.intensity import equalize_image, equalize_point_intensities

    config = config or PreprocessConfig()
    log = log or (lambda line: None)
    if getattr(pair.scans, "deferred", False):
        check_scans(pair)
    mode = choose_mode(pair, config)
    t0 = time.perf_counter()
    log(f"{pair.name}: {len(pair.scans)} scan(s), {mode} integration")
    cloud = _shared_cloud(pair, mode, config, progress=progress and len(pair.scans) > 3)
    if len(cloud) == 0:
        raise InputError(
            f"pair '{pair.name}': no point left after accumulation "
            f"(all within {config.min_distance} m of the sensor?)"
        )
    points, summary = cloud.points, {}
    if pair.image_scan is not None:
        summary = dict(pair.info)
        if mode == "dynamic":
            points, offset = _at_image_time(cloud, pair.image_scan, pair.image_fraction)
            summary["image_frame_offset_m"] = offset
            log(f"{pair.name}: cloud at the image time, {offset:.3f} m from the first scan's start")
    intensities = cloud.intensity
    if config.equalize:
        intensities = equalize_point_intensities(intensities)
        image = equalize_image(pair.image)
    else:
        top = float(np.max(intensities)) if intensities.size else 1.0
        intensities = np.clip(intensities / (top if top > 0 else 1.0), 0.0, 1.0)
        image = _to_uint8(pair.image)
    # the work directory's PLY holds float32: keep exactly those values
    points = points.astype(np.float32).astype(np.float64)
    intensities = np.asarray(intensities, dtype=np.float32).astype(np.float64)
    summary = {"mode": mode, "scans": len(pair.scans), "points": len(points), **summary}
    log(f"{pair.name}: {len(points)} points, {time.perf_counter() - t0:.1f} s")
    return PairData(pair.name, image, points, intensities, summary=summary)


def choose_virtual_camera(pair: PairData, origin=None) -> VirtualCamera:
    """The virtual camera every pair is rendered with, chosen from ``pair``'s field of view.

    As the reference: one virtual camera for all pairs, a pinhole under 150 degrees, else
    equirectangular, placed at ``origin`` (where the LiDAR sits in the clouds' frame; default
    the clouds' origin) and measuring the field of view from there.
    """
    from nbcalib.preprocess.lidar_image import estimate_lidar_fov, make_virtual_camera

    o = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64)
    fov = estimate_lidar_fov(pair.points_lidar - o if o.any() else pair.points_lidar)
    camera, T_vcam_lidar = make_virtual_camera(fov)
    if o.any():  # the camera at the LiDAR: p_vcam = R (p - o)
        T_vcam_lidar[:3, 3] = -T_vcam_lidar[:3, :3] @ o
    return VirtualCamera(camera, T_vcam_lidar, math.degrees(fov))


def render_pair(virtual: VirtualCamera, pair: PairData) -> PairData:
    """``pair`` with its LiDAR intensity image and index map rendered by ``virtual``."""
    from nbcalib.preprocess.lidar_image import render_lidar_image

    image = render_lidar_image(
        virtual.camera, virtual.T_vcam_lidar, pair.points_lidar, pair.intensities
    )
    filled = int(np.count_nonzero(image.index >= 0))
    summary = {**(pair.summary or {}), "lidar_image_filled_pixels": filled}
    return replace(pair, lidar_image=image, summary=summary)


def render_pairs(
    pairs: Sequence[PairData],
    virtual: VirtualCamera | None = None,
    *,
    origin=None,
    log: Callable[[str], None] | None = None,
) -> tuple[VirtualCamera, list[PairData]]:
    """Render every pair's LiDAR image and index map with one virtual camera.

    Parameters
    ----------
    pairs : sequence of PairData
        Dense clouds (:func:`prepare_pair`).
    virtual : VirtualCamera, optional
        The camera to render with; default: chosen from the first pair's LiDAR field of view
        (:func:`choose_virtual_camera`).
    origin : array_like of shape (3,), optional
        Where the LiDAR sits in the clouds' frame (:mod:`nbcalib.preprocess.origin`): the
        default camera is placed there and the field of view measured from there (default:
        the clouds' origin).
    log : callable, optional
        Receives progress lines.

    Returns
    -------
    virtual : VirtualCamera
    pairs : list of PairData
        The same pairs with ``lidar_image`` set (:func:`render_pair`).
    """
    log = log or (lambda line: None)
    if not pairs:
        raise ValueError("render_pairs needs at least one pair")
    if virtual is None:
        virtual = choose_virtual_camera(pairs[0], origin)
        log(describe_virtual_camera(virtual))
    return virtual, thread_map(lambda pair: render_pair(virtual, pair), pairs)  # every core


def describe_virtual_camera(virtual: VirtualCamera) -> str:
    """One line: the field of view measured and the virtual camera it chose."""
    return f"LiDAR field of view {virtual.fov_deg:.1f} deg: {virtual.camera.model} virtual camera"
