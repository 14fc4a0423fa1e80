"""Virtual LiDAR views shaped like the camera: what the matchers see instead of the panorama.

A 360-degree spinning LiDAR's equirectangular image shows the camera's view as a small strip
(about 470 x 140 px of 1920 x 960 for KITTI), bent by the equirectangular projection and at a
different scale. Matchers trained on photographs want two images of the same geometry. A
:class:`LidarView` renders the dense cloud through *the real camera's own model* (its distortion
included), with the intrinsics scaled to the LiDAR's angular resolution, from the LiDAR origin,
looking along a hypothesised heading. When the heading is near the true one, the view and the
camera image differ only by a small rotation and the camera-LiDAR parallax.

- :func:`heading_rotations`: ``R_vcam_lidar`` of level views at evenly spaced headings (no
  prior: a spinning LiDAR's camera may look anywhere around it).
- :func:`prior_rotations`: views around a rough prior orientation.
- :func:`scaled_camera`: the camera with intrinsics and image size scaled by ``s``.
- :func:`render_view`: z-buffer rendering plus densification (range-dependent splat, then hole
  filling).

The view's index map lifts its keypoints to cloud rows (as the stored LiDAR image's does).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel, create_camera

__all__ = [
    "DEFAULT_PIXELS_PER_DEGREE",
    "LidarView",
    "heading_rotations",
    "inpaint_coverage",
    "prior_rotations",
    "render_view",
    "scaled_camera",
    "view_scale",
]

#: Angular resolution of the views by default, pixels per degree: that of the 1920-px-wide
#: equirectangular LiDAR image of preprocessing (docs/BENCHMARKS.md, "Matching").
DEFAULT_PIXELS_PER_DEGREE = 1920 / 360.0

#: Camera axes (rows, LiDAR coordinates) of a level camera looking along LiDAR +x.
_R_FORWARD = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])


@dataclass(frozen=True)
class LidarView:
    """A LiDAR image rendered through (a scaled copy of) the real camera at one orientation.

    Attributes
    ----------
    camera : CameraModel
        The virtual camera: the real camera's model, intrinsics scaled by ``scale``.
    T_vcam_lidar : ndarray of shape (4, 4), float64
        ``p_vcam = T_vcam_lidar @ p_lidar`` (a rotation, or the prior pose).
    intensity : ndarray of shape (h, w), uint8
        Densified intensity image (0 = empty).
    index : ndarray of shape (h, w), int32
        Cloud row per pixel of the z-buffer (and splat), -1 where empty; holes filled in
        ``intensity`` are empty here, so that a keypoint lifts to the *nearest* point within the
        search radius (:func:`~nbcalib.matching.correspondences.lift_lidar_pixels`), not
        to the one the fill happened to copy.
    scale : float
        Real camera pixels to view pixels (``camera_scale`` of :func:`match_images`).
    heading_deg : float
        Yaw of the optical axis about LiDAR z, degrees (0 = LiDAR +x, 90 = +y).
    """

    camera: CameraModel
    T_vcam_lidar: np.ndarray
    intensity: np.ndarray
    index: np.ndarray
    scale: float
    heading_deg: float

    @property
    def fill_fraction(self) -> float:
        """Fraction of the view's pixels that show something (after hole filling)."""
        return float(np.count_nonzero(self.intensity > 0)) / self.intensity.size


def _level_rotation(heading: float) -> np.ndarray:
    """``R_vcam_lidar`` of a level camera whose optical axis has yaw ``heading`` (radians)."""
    c, s = math.cos(heading), math.sin(heading)
    R_lidar_heading = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return _R_FORWARD @ R_lidar_heading.T


def heading_rotations(n_headings: int, *, offset_deg: float = 0.0) -> list[np.ndarray]:
    """Rotations ``R_vcam_lidar`` of level views at ``n_headings`` evenly spaced headings.

    Heading ``k`` looks along yaw ``offset_deg + 360 k / n_headings`` degrees about LiDAR z
    (0 = LiDAR +x); camera x = right, y = down (LiDAR -z), z = the optical axis.

    Parameters
    ----------
    n_headings : int
        Number of views (>= 1).
    offset_deg : float, optional
        Yaw of the first view, degrees.

    Returns
    -------
    list of ndarray of shape (3, 3), float64
    """
    if int(n_headings) != n_headings or n_headings < 1:
        raise ValueError(f"n_headings must be a positive integer, got {n_headings}")
    step = 2.0 * math.pi / n_headings
    return [_level_rotation(math.radians(offset_deg) + k * step) for k in range(int(n_headings))]


def prior_rotations(R_camera_lidar, yaw_offsets_deg=(0.0,)) -> list[np.ndarray]:
    """Rotations ``R_vcam_lidar`` around a prior camera orientation, turned about LiDAR z.

    Parameters
    ----------
    R_camera_lidar : array_like of shape (3, 3)
        Rotation of the prior ``T_camera_lidar``.
    yaw_offsets_deg : sequence of float, optional
        Extra yaw of each view about LiDAR z, degrees (0: the prior itself).

    Returns
    -------
    list of ndarray of shape (3, 3), float64
    """
    R = np.asarray(R_camera_lidar, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"R_camera_lidar must be a finite 3 x 3 matrix, got shape {R.shape}")
    out = []
    for yaw in yaw_offsets_deg:
        c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
        R_lidar_turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        out.append(R @ R_lidar_turn.T)
    return out


def scaled_camera(camera: CameraModel, scale: float) -> CameraModel:
    """The same camera model with image size and intrinsics scaled by ``scale``.

    Focal lengths scale by ``s``, principal points as pixel centres: ``c' = (c + 0.5) s - 0.5``;
    the distortion (in normalised coordinates) is unchanged. An equirectangular camera gets the
    scaled size. The image size is rounded, so the true per-axis factors differ slightly; the
    intrinsics are scaled by ``size' / size`` per axis, which keeps the image border in place.

    Parameters
    ----------
    camera : CameraModel
        A camera.
    scale : float
        Factor (> 0).

    Returns
    -------
    CameraModel
    """
    if not (math.isfinite(scale) and scale > 0.0):
        raise ValueError(f"scale must be a finite number > 0, got {scale}")
    width = max(round(camera.width * scale), 1)
    height = max(round(camera.height * scale), 1)
    if camera.model == "equirectangular":
        return create_camera("equirectangular", [width, height], [], width, height)
    su, sv = width / camera.width, height / camera.height
    intr = np.array(camera.intrinsics, dtype=np.float64)
    intr[0] *= su
    intr[1] *= sv
    intr[2] = (intr[2] + 0.5) * su - 0.5
    intr[3] = (intr[3] + 0.5) * sv - 0.5
    return create_camera(camera.model, intr, camera.distortion_coeffs, width, height)


def view_scale(camera: CameraModel, pixels_per_degree: float = DEFAULT_PIXELS_PER_DEGREE) -> float:
    """Factor that gives ``camera`` about ``pixels_per_degree`` at its image centre (<= 1)."""
    from nbcalib.matching.match import pixels_per_radian

    if not (math.isfinite(pixels_per_degree) and pixels_per_degree > 0.0):
        raise ValueError(f"pixels_per_degree must be > 0, got {pixels_per_degree}")
    own = pixels_per_radian(camera) * math.pi / 180.0
    return min(1.0, pixels_per_degree / own)


def _splat(index: np.ndarray, depth: np.ndarray, radius_of_range) -> np.ndarray:
    """Grow each filled pixel into its empty neighbours, nearer points first, up to a radius.

    An empty pixel takes the point of the nearest (by range) filled pixel within a Chebyshev
    distance ``r`` for which ``r <= radius_of_range(range)``: near points are large on the
    image and cover the holes between their scan lines, far points stay small.
    """
    import cv2

    out = index.copy()
    best = np.where(index >= 0, depth, np.inf).astype(np.float32)
    reach = radius_of_range(np.where(np.isfinite(best), best, 0.0))
    r_max = int(np.max(reach, initial=0))
    empty = index < 0
    for r in range(1, r_max + 1):
        kernel = np.ones((2 * r + 1, 2 * r + 1), np.uint8)
        allowed = np.where((reach >= r) & (index >= 0), best, np.inf).astype(np.float32)
        # nearest range among allowed pixels within r: an erosion (min filter) of the ranges
        near = cv2.erode(allowed, kernel, borderType=cv2.BORDER_CONSTANT, borderValue=np.inf)
        take = empty & np.isfinite(near) & (near < np.where(out >= 0, best, np.inf))
        if not np.any(take):
            continue
        # which pixel holds that range: compare each shifted candidate (r is small)
        for dv in range(-r, r + 1):
            for du in range(-r, r + 1):
                shifted = np.full_like(allowed, np.inf)
                src_idx = np.full(index.shape, -1, dtype=index.dtype)
                h, w = index.shape
                vs, vd = (
                    (slice(0, h - dv), slice(dv, h))
                    if dv >= 0
                    else (slice(-dv, h), slice(0, h + dv))
                )
                us, ud = (
                    (slice(0, w - du), slice(du, w))
                    if du >= 0
                    else (slice(-du, w), slice(0, w + du))
                )
                shifted[vd, ud] = allowed[vs, us]
                src_idx[vd, ud] = index[vs, us]
                hit = take & (shifted == near) & (out < 0)
                out[hit] = src_idx[hit]
        best = np.where(out >= 0, np.where(index >= 0, best, np.inf), np.inf).astype(np.float32)
    return out


def render_view(
    camera: CameraModel,
    R_vcam_lidar,
    points_lidar,
    intensities,
    *,
    scale: float,
    t_vcam_lidar=None,
    fill_radius: int = 2,
    splat_pixels_at_1m: float = 0.0,
    max_splat: int = 3,
    median: int = 0,
    inpaint: int = 0,
    heading_deg: float | None = None,
) -> LidarView:
    """Render the dense cloud through the scaled real camera at one orientation.

    Steps: z-buffer (:func:`nbcalib.preprocess.lidar_image.render_lidar_image`, nearest point
    per pixel), an optional range-dependent splat (a point at range ``d`` covers empty pixels
    up to ``min(max_splat, splat_pixels_at_1m / d)`` pixels away, nearer points win), then hole
    filling of the intensities within ``fill_radius`` pixels (through a filled copy of the
    index map). The returned ``index`` is not filled: lift keypoints with a search radius of at
    least ``fill_radius`` (:func:`~nbcalib.matching.multiview.match_views` does).

    Parameters
    ----------
    camera : CameraModel
        The real camera.
    R_vcam_lidar : array_like of shape (3, 3)
        Orientation of the view (:func:`heading_rotations`, :func:`prior_rotations`).
    points_lidar : array_like of shape (N, 3)
        Dense cloud, LiDAR frame, metres.
    intensities : array_like of shape (N,)
        Equalised intensities in [0, 1].
    scale : float
        Intrinsics scale (:func:`view_scale`).
    t_vcam_lidar : array_like of shape (3,), optional
        Translation of the view (default 0: the LiDAR origin).
    fill_radius : int, optional
        Hole-filling radius, pixels (0: off).
    splat_pixels_at_1m : float, optional
        Splat radius of a point 1 m away, pixels (0: no splat).
    max_splat : int, optional
        Largest splat radius, pixels.
    median : int, optional
        Median filter size (odd, pixels; 0: off) applied to the filled intensities against the
        speckle of per-point reflectance (accumulated clouds); empty pixels stay 0.
    inpaint : int, optional
        Fill every hole of the LiDAR's coverage narrower than this many pixels by inpainting
        (:func:`inpaint_coverage`; 0: off), after ``fill_radius`` and ``median``: a scan's
        rings become surfaces, which learned matchers can match to a photograph.
    heading_deg : float, optional
        Recorded heading (default: computed from the optical axis).

    Returns
    -------
    LidarView
    """
    from nbcalib.preprocess.lidar_image import intensity_to_uint8, render_lidar_image

    R = np.asarray(R_vcam_lidar, dtype=np.float64)
    if R.shape != (3, 3) or not np.all(np.isfinite(R)):
        raise ValueError(f"R_vcam_lidar must be a finite 3 x 3 matrix, got shape {R.shape}")
    T = np.eye(4)
    T[:3, :3] = R
    if t_vcam_lidar is not None:
        T[:3, 3] = np.asarray(t_vcam_lidar, dtype=np.float64).reshape(3)
    vcam = scaled_camera(camera, scale)
    image = render_lidar_image(vcam, T, points_lidar, intensities)
    index = image.index
    if splat_pixels_at_1m > 0.0 and max_splat > 0:

        def radius_of_range(d):
            with np.errstate(divide="ignore"):
                r = np.where(d > 0, np.floor(splat_pixels_at_1m / np.maximum(d, 1e-9)), 0)
            return np.minimum(r, max_splat).astype(np.int64)

        index = _splat(index, image.depth, radius_of_range)
    if fill_radius > 0:
        shown = _fill_index(index, fill_radius)
    else:
        shown = index
    # 0 marks empty pixels: a point of intensity 0 is shown as 1
    values = intensity_to_uint8(np.asarray(intensities, dtype=np.float64))
    intensity = np.zeros(index.shape, dtype=np.uint8)
    filled = shown >= 0
    intensity[filled] = np.maximum(values[shown[filled]], 1)
    if median:
        import cv2

        if median < 3 or median % 2 == 0:
            raise ValueError(f"median must be 0 or an odd size >= 3, got {median}")
        intensity = np.where(filled, np.maximum(cv2.medianBlur(intensity, median), 1), 0)
        intensity = intensity.astype(np.uint8)
    if inpaint:
        intensity = inpaint_coverage(intensity, inpaint)
    if heading_deg is None:
        axis = R[2]  # optical axis in LiDAR coordinates
        heading_deg = math.degrees(math.atan2(axis[1], axis[0]))
    return LidarView(vcam, T, intensity, index, float(scale), float(heading_deg))


def inpaint_coverage(intensity: np.ndarray, width: int) -> np.ndarray:
    """Inpaint the holes of a LiDAR image inside its coverage (0 = empty stays outside it).

    The coverage is the morphological closing of the filled pixels with a ``width`` x ``width``
    square: gaps between rings and between sparse points narrower than ``width`` belong to it,
    the sky above the top ring and the ground below the lowest do not. Holes inside it are
    filled by OpenCV's Telea inpainting (radius 3) from the shown pixels only; the result is
    >= 1 there, 0 outside.

    Parameters
    ----------
    intensity : ndarray of shape (h, w), uint8
        LiDAR image, 0 where empty.
    width : int
        Widest gap filled, pixels (>= 1).

    Returns
    -------
    ndarray of shape (h, w), uint8
    """
    import cv2

    img = np.asarray(intensity)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ValueError(f"intensity must be a 2-D uint8 image, got {img.dtype} {img.shape}")
    width = int(width)
    if width < 1:
        raise ValueError(f"width must be >= 1, got {width}")
    filled = (img > 0).astype(np.uint8)
    cover = cv2.morphologyEx(filled, cv2.MORPH_CLOSE, np.ones((width, width), np.uint8))
    holes = (cover > 0) & (filled == 0)
    if not holes.any():
        return img.copy()
    # every empty pixel is unknown to the inpainting (else the empty outside, 0, bleeds into
    # the coverage's border); only the holes inside the coverage are kept
    out = cv2.inpaint(img, (filled == 0).astype(np.uint8), 3, cv2.INPAINT_TELEA)
    out = np.where(cover > 0, np.maximum(out, 1), 0).astype(np.uint8)
    return out


def _fill_index(index: np.ndarray, radius: int) -> np.ndarray:
    """Give each empty pixel the cloud row of a filled pixel at most ``radius`` away.

    One ring at a time (Chebyshev distance 1, 2, ...), the row of the first filled neighbour
    in a fixed order (up, down, left, right, then diagonals): deterministic, and no new values.
    """
    out = index.copy()
    h, w = out.shape
    order = [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (-1, 1), (1, -1), (1, 1)]
    for _ in range(int(radius)):
        empty = out < 0
        if not np.any(empty):
            break
        new = out.copy()
        for dv, du in order:
            src = np.full_like(out, -1)
            vs, vd = (
                (slice(0, h - dv), slice(dv, h)) if dv >= 0 else (slice(-dv, h), slice(0, h + dv))
            )
            us, ud = (
                (slice(0, w - du), slice(du, w)) if du >= 0 else (slice(-du, w), slice(0, w + du))
            )
            src[vd, ud] = out[vs, us]
            take = empty & (new < 0) & (src >= 0)
            new[take] = src[take]
        out = new
    return out
