"""The LiDAR virtual camera: field of view, camera choice, z-buffer rendering, hidden points.

Paper section III-D and reference_toolbox.md section 4. The dense cloud is rendered through a
virtual camera at the LiDAR origin into an 8-bit intensity image (the input of the learned
matcher) and an int32 index map (pixel -> row of the cloud, -1 where empty) that lifts LiDAR-image
keypoints to 3-D points.

- :func:`estimate_lidar_fov`: the largest angle between two point directions.
- :func:`make_virtual_camera`: pinhole below 150 degrees, equirectangular otherwise, oriented as
  the reference toolbox.
- :func:`render_lidar_image`: z-buffer rendering, wraps the kernels of
  :mod:`nbcalib.kernels.zbuffer` (semantics and tie rule documented there).
- :func:`visible_mask`: hidden-point removal with the same z-buffer (for the fine registration).

Differences from the reference toolbox:

- Pixels: the nearest pixel is ``floor(u + 0.5)`` and the pinhole's principal point is
  ``(W - 1) / 2 = 511.5`` (pixel centres at integers, docs/conventions.md section 6); the
  reference truncates and uses 512, the same picture under its convention.
- Field of view: the exact largest angle between the directions of the points (see
  :func:`estimate_lidar_fov`). The reference measures it among the vertices of the convex hull
  of the *points* only, which can underestimate wide fields of view.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nbcalib.camera import CameraModel, create_camera
from nbcalib.errors import InputError
from nbcalib.kernels import zbuffer as _k

__all__ = [
    "PINHOLE_MAX_FOV_DEG",
    "R_VCAM_LIDAR_EQUIRECTANGULAR",
    "R_VCAM_LIDAR_PINHOLE",
    "LidarImage",
    "estimate_lidar_fov",
    "intensity_to_uint8",
    "make_virtual_camera",
    "render_lidar_image",
    "visibility",
    "visible_indices",
    "visible_mask",
]

#: Below this field of view the virtual camera is a pinhole, otherwise equirectangular (paper).
PINHOLE_MAX_FOV_DEG = 150.0

#: Pinhole virtual camera: optical axis (camera z) = LiDAR +x, camera x = LiDAR -y, camera y =
#: LiDAR -z. Rows are the camera axes in LiDAR coordinates (the reference's Ry(90) Rz(-90),
#: transposed).
R_VCAM_LIDAR_PINHOLE = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]])

#: Equirectangular virtual camera: camera x = LiDAR x, camera y = LiDAR -z, camera z = LiDAR +y
#: (the reference's Rx(-90)): the image centre looks along LiDAR +y, LiDAR +x is at
#: ``u = 0.75 W - 0.5`` and up is at the top.
R_VCAM_LIDAR_EQUIRECTANGULAR = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

# Farthest-point iterations for the lower bound of the field of view; brute force above this many
# candidate directions switches to a k-d tree of the antipodes.
_FARTHEST_POINT_ITERATIONS = 4
_BRUTE_FORCE_MAX = 8000
_CHUNK = 2048
# Directions thinner than this (rms distance from their best plane through the sensor, on the
# unit sphere; ~0.06 degree) span no solid angle: a 2-D scanner, or a single line of points.
_MIN_THICKNESS = 1e-3


# --------------------------------------------------------------------------------------------
# Field of view


def estimate_lidar_fov(points_lidar, *, voxel_size: float = 0.2, min_range: float = 1.0) -> float:
    """Field of view of a LiDAR: the largest angle between the directions of two of its points.

    As the paper (section III-D) and the reference: drop points nearer than ``min_range``,
    voxel-downsample the rest (one point per ``voxel_size`` cube, the first in input order), then
    find the pair of directions with the largest angle. A 360-degree spinning LiDAR gives about
    180 degrees; a cone-shaped field of view gives its full (diagonal) opening angle.

    Notes
    -----
    The largest angle between unit vectors is the diameter of the set of directions. The
    reference takes the convex hull of the *points*, normalises the hull's vertices and
    brute-forces their pairs. That is exact for a pointed, cone-shaped field of view whose
    widest pair are hull vertices, but a point inside the hull can realise a larger angle once
    angles exceed 90 degrees (the angle to a fixed direction is not quasi-convex there), e.g. a
    near point behind the sensor inside the hull of far points around it: the reference then
    underestimates the field of view and may pick a pinhole camera (tested). The hull of the
    *directions* would be exact, but every direction lies on the unit sphere, so every one is a
    hull vertex (all 114 278 of a KITTI scan) and the hull prunes nothing. nbcalib computes the
    exact maximum instead:

    1. a lower bound ``L`` from a few farthest-point iterations (each ``O(N)``);
    2. with ``c`` the mean direction, ``r_i`` the angle of direction ``i`` to ``c`` and
       ``R = max r_i``, a pair can only beat ``L`` if both ``r_i, r_j > L - R`` (triangle
       inequality on the sphere), which keeps a thin rim of a cone-shaped field of view;
    3. among those candidates, brute force (chunked dot products) or, when there are many (the
       wrap-around case, where the bound prunes little), the nearest antipode in a k-d tree:
       the largest angle is ``pi - 2 asin(min |d_i + d_j| / 2)``.

    Parameters
    ----------
    points_lidar : array_like of shape (N, 3)
        Points in the LiDAR frame, metres (non-finite rows are ignored).
    voxel_size : float, optional
        Edge of the downsampling voxels, metres; 0 disables downsampling.
    min_range : float, optional
        Points nearer to the sensor than this are ignored, metres.

    Returns
    -------
    float
        The field of view in radians, in ``[0, pi]``.

    Raises
    ------
    InputError
        Fewer than 4 usable points, or all directions in one plane through the sensor (a 2-D
        scan: no virtual camera can show it).
    """
    pts = np.asarray(points_lidar, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points_lidar must have shape (N, 3), got {pts.shape}")
    if not (voxel_size >= 0.0 and min_range >= 0.0):
        raise ValueError(f"voxel_size and min_range must be >= 0, got {voxel_size}, {min_range}")
    pts = pts[np.all(np.isfinite(pts), axis=1)]
    ranges = np.linalg.norm(pts, axis=1)
    keep = (ranges >= min_range) & (ranges > 0.0)
    pts, ranges = pts[keep], ranges[keep]
    if voxel_size > 0.0 and len(pts):
        first = _first_per_voxel(pts, voxel_size)
        pts, ranges = pts[first], ranges[first]
    if len(pts) < 4:
        raise InputError(
            f"cannot estimate the LiDAR field of view: only {len(pts)} points are farther than "
            f"{min_range:g} m from the sensor (need at least 4)"
        )
    directions = pts / ranges[:, None]
    thickness = np.linalg.svd(directions, compute_uv=False)[2] / math.sqrt(len(directions))
    if thickness < _MIN_THICKNESS:
        raise InputError(
            "cannot build a LiDAR image: all points lie in one plane through the sensor "
            "(a 2-D scan has no field of view to render)"
        )
    return _largest_angle(directions)


def _first_per_voxel(points: np.ndarray, voxel_size: float) -> np.ndarray:
    """Indices of the first point (in input order) of every occupied voxel, ascending."""
    keys = np.floor(points / voxel_size).astype(np.int64)
    keys -= keys.min(axis=0)
    extent = keys.max(axis=0) + 1
    if float(extent[0]) * float(extent[1]) * float(extent[2]) < 2.0**62:
        flat = (keys[:, 0] * extent[1] + keys[:, 1]) * extent[2] + keys[:, 2]
        _, first = np.unique(flat, return_index=True)
    else:  # a cloud spanning thousands of km: row-wise unique (slower, never in practice)
        _, first = np.unique(keys, axis=0, return_index=True)
    return np.sort(first)


def _largest_angle(directions: np.ndarray) -> float:
    """Exact largest angle between two unit vectors (rows); see :func:`estimate_lidar_fov`."""
    mean = directions.mean(axis=0)
    norm = np.linalg.norm(mean)
    centre = mean / norm if norm > 1e-9 else directions[0]
    r = np.arccos(np.clip(directions @ centre, -1.0, 1.0))
    # lower bound: farthest-point iterations from the direction farthest from the centre
    i = int(np.argmax(r))
    best_cos = 1.0
    for _ in range(_FARTHEST_POINT_ITERATIONS):
        dots = directions @ directions[i]
        j = int(np.argmin(dots))
        best_cos = min(best_cos, float(dots[j]))
        i = j
    lower = math.acos(max(-1.0, min(1.0, best_cos)))
    # both members of a better pair lie beyond lower - R from the centre (slack for rounding)
    candidates = directions[r >= lower - r.max() - 1e-9]
    if len(candidates) <= _BRUTE_FORCE_MAX:
        for start in range(0, len(candidates), _CHUNK):
            block = candidates[start : start + _CHUNK] @ candidates.T
            best_cos = min(best_cos, float(block.min()))
        return math.acos(max(-1.0, min(1.0, best_cos)))
    from scipy.spatial import cKDTree

    chord, _ = cKDTree(candidates).query(-candidates, k=1)
    antipode_angle = 2.0 * math.asin(min(1.0, float(chord.min()) / 2.0))
    return max(lower, math.pi - antipode_angle)


# --------------------------------------------------------------------------------------------
# Virtual camera


def make_virtual_camera(
    fov: float,
    *,
    pinhole_size: int = 1024,
    equirectangular_size: tuple[int, int] = (1920, 960),
    pinhole_max_fov_deg: float = PINHOLE_MAX_FOV_DEG,
) -> tuple[CameraModel, np.ndarray]:
    """The virtual camera that renders a LiDAR of the given field of view (paper III-D).

    - ``fov < pinhole_max_fov_deg``: a ``pinhole`` camera of ``pinhole_size`` squared pixels with
      ``fx = fy = size / (2 tan(fov / 2))`` and ``cx = cy = (size - 1) / 2`` (511.5 for 1024;
      the reference's 512 is the same under its truncating pixel convention), looking along
      LiDAR +x (:data:`R_VCAM_LIDAR_PINHOLE`).
    - otherwise an ``equirectangular`` camera of ``equirectangular_size`` (W, H), oriented by
      :data:`R_VCAM_LIDAR_EQUIRECTANGULAR` (LiDAR +x at ``u = 0.75 W - 0.5``, up at the top).

    The camera sits at the LiDAR origin in both cases.

    Parameters
    ----------
    fov : float
        LiDAR field of view in radians, in ``(0, pi]`` (:func:`estimate_lidar_fov`).
    pinhole_size : int, optional
        Width = height of the pinhole image, pixels.
    equirectangular_size : tuple of int, optional
        ``(W, H)`` of the equirectangular image, pixels.
    pinhole_max_fov_deg : float, optional
        Field of view (degrees) from which on the equirectangular camera is used.

    Returns
    -------
    camera : CameraModel
        The virtual camera.
    T_vcam_lidar : ndarray of shape (4, 4), float64
        ``p_vcam = T_vcam_lidar @ p_lidar``: a pure rotation.
    """
    if not (0.0 < fov <= math.pi):
        raise ValueError(f"fov must be in (0, pi] radians, got {fov}")
    if not 0.0 < pinhole_max_fov_deg < 180.0:
        raise ValueError(f"pinhole_max_fov_deg must be in (0, 180), got {pinhole_max_fov_deg}")
    T_vcam_lidar = np.eye(4)
    if math.degrees(fov) < pinhole_max_fov_deg:
        size = int(pinhole_size)
        if size != pinhole_size or size <= 0:
            raise ValueError(f"pinhole_size must be a positive integer, got {pinhole_size}")
        f = size / (2.0 * math.tan(fov / 2.0))
        c = (size - 1) / 2.0
        camera = create_camera("pinhole", [f, f, c, c], [], size, size)
        T_vcam_lidar[:3, :3] = R_VCAM_LIDAR_PINHOLE
    else:
        width, height = (int(s) for s in equirectangular_size)
        camera = create_camera("equirectangular", [width, height], [], width, height)
        T_vcam_lidar[:3, :3] = R_VCAM_LIDAR_EQUIRECTANGULAR
    return camera, T_vcam_lidar


# --------------------------------------------------------------------------------------------
# Rendering


@dataclass(frozen=True)
class LidarImage:
    """A rendered LiDAR image: what the nearest point of each pixel shows.

    Attributes
    ----------
    intensity : ndarray of shape (H, W), uint8
        ``round(255 * intensity)`` of the nearest point (0 where empty).
    index : ndarray of shape (H, W), int32
        Row of the nearest point in the rendered cloud, -1 where empty.
    depth : ndarray of shape (H, W), float32
        Range of the nearest point from the camera centre, metres; inf where empty.
    """

    intensity: np.ndarray
    index: np.ndarray
    depth: np.ndarray

    @property
    def filled(self) -> np.ndarray:
        """Boolean (H, W) mask of pixels that show a point."""
        return self.index >= 0


def intensity_to_uint8(intensities) -> np.ndarray:
    """``round(255 * x)`` (half to even, as OpenCV's ``saturate_cast``), clipped to 0..255.

    Parameters
    ----------
    intensities : array_like of shape (N,)
        Equalised intensities in [0, 1] (values outside are clipped).

    Returns
    -------
    ndarray of shape (N,), uint8
    """
    x = np.asarray(intensities, dtype=np.float64)
    return np.clip(np.rint(255.0 * x), 0, 255).astype(np.uint8)


def _check_inputs(camera, T, points, name_T):
    if not isinstance(camera, CameraModel):
        raise ValueError(f"camera must be a CameraModel, got {type(camera).__name__}")
    T = np.ascontiguousarray(T, dtype=np.float64)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name_T} must be a finite 4 x 4 matrix, got shape {T.shape}")
    # float32 points (a work directory's cloud, a view of its x, y, z, intensity rows) go in as
    # they are: the kernels widen each coordinate exactly before any arithmetic, so the result
    # is the float64 cloud's, bit for bit, with no copy of the whole cloud
    if not (isinstance(points, np.ndarray) and points.dtype == np.float32):
        points = np.ascontiguousarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points_lidar must have shape (N, 3), got {points.shape}")
    if points.shape[0] > np.iinfo(np.int32).max:
        raise ValueError(f"at most 2**31 - 1 points fit an int32 index map, got {len(points)}")
    return T, points


def _zbuffer(camera, T, points):
    """Run the two z-buffer kernels; flat buffers plus the per-point pixels and squared ranges."""
    n = points.shape[0]
    width, height = camera.width, camera.height
    pixel = np.empty(n, dtype=np.int64)
    range2 = np.empty(n, dtype=np.float64)
    _k._project_to_pixels(camera.model_id, camera.params, T, points, width, height, pixel, range2)
    best_range2 = np.full(width * height, np.inf)
    index = np.full(width * height, -1, dtype=np.int32)
    _k._scatter_nearest(pixel, range2, best_range2, index)
    return best_range2, index, pixel, range2


def render_lidar_image(
    camera: CameraModel,
    T_camera_lidar,
    points_lidar,
    intensities,
) -> LidarImage:
    """Render points into a camera: nearest point per pixel, its intensity, index and range.

    Wraps :func:`nbcalib.kernels.zbuffer._project_to_pixels` and
    :func:`~nbcalib.kernels.zbuffer._scatter_nearest`. Each point goes to its nearest pixel
    ``floor(u + 0.5)``; points that are invalid for the camera (behind it, outside its domain,
    non-finite) or off the image are skipped; the z-buffer keeps the smallest squared range per
    pixel, and on equal ranges the point with the larger index (the reference's last writer). No
    splatting, no hole filling (as the paper).

    Parameters
    ----------
    camera : CameraModel
        The virtual camera (:func:`make_virtual_camera`) or any real camera.
    T_camera_lidar : array_like of shape (4, 4)
        ``p_camera = T_camera_lidar @ p_lidar``.
    points_lidar : array_like of shape (N, 3)
        Points in the LiDAR frame, metres; NaN rows are allowed (skipped).
    intensities : array_like of shape (N,)
        Equalised intensities in [0, 1] (:func:`nbcalib.preprocess.intensity.
        equalize_point_intensities`), stored as ``round(255 x)``.

    Returns
    -------
    LidarImage
    """
    T, points = _check_inputs(camera, T_camera_lidar, points_lidar, "T_camera_lidar")
    values = np.asarray(intensities, dtype=np.float64)
    if values.shape != (points.shape[0],):
        raise ValueError(f"intensities must have shape ({points.shape[0]},), got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError("intensities must be finite")
    best_range2, index, _, _ = _zbuffer(camera, T, points)
    shape = (camera.height, camera.width)
    depth = np.empty(best_range2.shape, dtype=np.float32)
    _k._range_map(best_range2, depth)
    intensity = np.zeros(best_range2.shape, dtype=np.uint8)
    filled = index >= 0
    intensity[filled] = intensity_to_uint8(values)[index[filled]]
    return LidarImage(intensity.reshape(shape), index.reshape(shape), depth.reshape(shape))


def visible_mask(
    camera: CameraModel,
    T_camera_lidar,
    points_lidar,
    *,
    margin: float = 0.1,
    window: int = 0,
) -> np.ndarray:
    """Hidden-point removal: which points the camera sees, not occluded by nearer ones.

    A point is visible when it projects into the image (same rules as
    :func:`render_lidar_image`) and its range is at most the smallest range found in its pixel,
    or in the ``(2 window + 1)^2`` pixels around it (clipped at the border), plus ``margin``.
    ``window=0`` and ``margin=0.1`` are the reference's view culling (run at the real camera's
    resolution). Wraps the z-buffer kernels and :func:`~nbcalib.kernels.zbuffer._min_filter`.

    Parameters
    ----------
    camera : CameraModel
        The camera that looks at the points.
    T_camera_lidar : array_like of shape (4, 4)
        ``p_camera = T_camera_lidar @ p_lidar``.
    points_lidar : array_like of shape (N, 3)
        Points in the LiDAR frame, metres.
    margin : float, optional
        Depth tolerance behind the nearest point, metres (>= 0).
    window : int, optional
        Half-size of the pixel neighbourhood (0: the point's own pixel only).

    Returns
    -------
    ndarray of shape (N,), bool
    """
    T, points = _check_inputs(camera, T_camera_lidar, points_lidar, "T_camera_lidar")
    mask, _ = _visibility(camera, T, points, margin, window)
    return mask


def visible_indices(
    camera: CameraModel,
    T_camera_lidar,
    points_lidar,
    *,
    margin: float = 0.1,
    window: int = 0,
    select=None,
) -> np.ndarray:
    """Indices of the points :func:`visible_mask` keeps, ordered by their pixel (row-major).

    Kernels that read the image around each point (the NID cost) then walk the image in memory
    order instead of the cloud's order, which on a 2 MP image misses the caches at almost every
    point. Measured on a synthetic 64-beam pair (190 k visible points, 1920 x 1080, serial CPU
    time, load ~13): the smooth NID value + gradient 1.34 x, the value 1.8 x and the
    hard-binned value 2.6 x faster than in cloud order. The pose changes little within an outer
    iteration of fine registration, so sorting once per cost keeps most of the gain. Ties keep
    the cloud's order (stable sort).

    Parameters
    ----------
    camera, T_camera_lidar, points_lidar, margin, window
        As :func:`visible_mask`.
    select : callable, optional
        Takes the visible indices in cloud order and returns the ones to keep (a subset, in
        the same order); applied before the sort, which then sorts only those.

    Returns
    -------
    ndarray of shape (M,), int64
        Indices into ``points_lidar``.
    """
    keep, pixel = visibility(camera, T_camera_lidar, points_lidar, margin=margin, window=window)
    return sorted_by_pixel(keep, pixel, select)


def visibility(
    camera: CameraModel, T_camera_lidar, points_lidar, *, margin: float = 0.1, window: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The visible points in cloud order and the flat pixel of every point.

    What :func:`visible_indices` orders: ``(keep (M,) int64, pixel (N,) int64)``, ``pixel``
    row-major, -1 off the image. Callers that need the visible set several times at one pose
    keep this and order it with :func:`sorted_by_pixel` (the z-buffer is the expensive part).
    """
    T, points = _check_inputs(camera, T_camera_lidar, points_lidar, "T_camera_lidar")
    mask, pixel = _visibility(camera, T, points, margin, window)
    return np.flatnonzero(mask), pixel


def sorted_by_pixel(keep: np.ndarray, pixel: np.ndarray, select=None) -> np.ndarray:
    """``keep`` (after ``select``, as :func:`visible_indices`) ordered by pixel, ties in order."""
    if select is not None:
        keep = select(keep)
    return keep[np.argsort(pixel[keep], kind="stable")]


def _visibility(camera, T, points, margin, window):
    """Visible mask (N,) and the flat pixel (N,) of every point (-1: off the image)."""
    if not margin >= 0.0:
        raise ValueError(f"margin must be >= 0, got {margin}")
    if int(window) != window or window < 0:
        raise ValueError(f"window must be a non-negative integer, got {window}")
    best_range2, _, pixel, range2 = _zbuffer(camera, T, points)
    min_range = np.sqrt(best_range2).reshape(camera.height, camera.width)
    if window > 0:
        min_range = _k._min_filter(min_range, int(window))
    out = np.empty(points.shape[0], dtype=np.bool_)
    _k._visible(pixel, range2, np.ascontiguousarray(min_range).ravel(), float(margin), out)
    return out, pixel
