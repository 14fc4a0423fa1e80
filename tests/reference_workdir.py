"""A work directory written the way the reference C++ toolbox writes it, from a tiny scene.

:func:`write_reference_workdir` writes what the reference's ``preprocess`` (and its
``find_matches_superglue.py``) leave in a directory, byte for byte as described in
reference_toolbox.md (sections 1.1, 1.3, 3.3 and 4), with its own code paths, not nbcalib's:

- ``<name>.ply``: Iridescence ``glk::save_ply_binary`` (koide3/iridescence ``save_ply``): the
  header below, with its ``comment generated with iridescence`` line, then float32 x, y, z,
  intensity little endian; vertices in a shuffled order (the voxel map's hash order);
- intensities equalised by rank, ``floor(256 i / N) / 256`` (section 3.3);
- ``<name>_lidar_intensities.png`` and ``<name>_lidar_indices.png``: the reference's virtual
  camera (1024 x 1024 ``plumb_bob`` with ``fx = 1024 / (2 tan(fov / 2))``, ``cx = cy = 512``
  below 150 degrees of LiDAR field of view, else 1920 x 960 equirectangular), *truncating*
  projection, squared-range z-buffer, ``convertTo(CV_8UC1, 255)`` and the int32 index map's
  bytes as BGRA, all written with ``cv2.imwrite``;
- ``<name>.png``: the camera image after ``cv2.equalizeHist``;
- ``calib.json``: ``camera`` and ``meta`` only (no ``nbcalib`` section), as nlohmann's
  ``dump(2)`` (keys sorted, indent 2) plus a newline;
- ``<name>_matches.json``: SuperGlue's ``json.dump`` of ``kpts0``, ``kpts1`` (whole pixels, as
  SuperPoint's), ``matches`` (-1 for unmatched) and ``confidence``; made from the truth, with
  a few keypoints on empty LiDAR pixels (which the reference drops) and a few wrong matches.

The scene is the textured cylinder wall of ``tests/test_matching_multiview.py``; the camera image
is that cloud rendered through the camera at the true pose, so fine registration has its
minimum at the truth. ``lidar="livox"`` keeps a 70-degree sector ahead (pinhole virtual
camera), ``lidar="spinning"`` the whole wall (equirectangular).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from nbcalib.camera import CameraModel, create_camera
from nbcalib.matching.views import render_view
from nbcalib.transforms import make_T
from tests.test_matching_multiview import _cylinder

__all__ = ["IRIDESCENCE_PLY_HEADER", "ReferenceWorkdir", "write_reference_workdir"]

#: ``glk::save_ply_binary``'s header for vertices with intensities (``{n}``: vertex count).
IRIDESCENCE_PLY_HEADER = (
    "ply\n"
    "format binary_little_endian 1.0\n"
    "comment generated with iridescence\n"
    "element vertex {n}\n"
    "property float x\n"
    "property float y\n"
    "property float z\n"
    "property float intensity\n"
    "end_header\n"
)

#: The reference's virtual camera orientations (``T_lidar_camera.linear()`` of preprocess.cpp).
R_LIDAR_VCAM_PINHOLE = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
R_LIDAR_VCAM_EQUIRECTANGULAR = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class ReferenceWorkdir:
    """What :func:`write_reference_workdir` wrote, and the truth behind it.

    Attributes
    ----------
    path : Path
        The directory.
    name : str
        The one bag name.
    camera : CameraModel
        The real camera (as ``calib.json`` holds it).
    T_camera_lidar : ndarray of shape (4, 4)
        The true extrinsic.
    points : ndarray of shape (N, 3), float32
        The cloud in ``.ply`` order.
    intensities : ndarray of shape (N,), float32
        Its equalised intensities.
    vcam_model : str
        ``plumb_bob`` or ``equirectangular``: the reference's virtual camera.
    vcam_intrinsics : list of float
        Its intrinsics as the reference built them.
    R_lidar_vcam : ndarray of shape (3, 3)
        Its orientation.
    index : ndarray of shape (H, W), int32
        The index map written.
    """

    path: Path
    name: str
    camera: CameraModel
    T_camera_lidar: np.ndarray
    points: np.ndarray
    intensities: np.ndarray
    vcam_model: str
    vcam_intrinsics: list
    R_lidar_vcam: np.ndarray
    index: np.ndarray


def _scene(rng, lidar: str, n: int, radius: float = 8.0):
    """The textured cylinder wall around the LiDAR (raw intensities in [0, 1])."""
    half = math.pi if lidar == "spinning" else math.radians(35.0)
    return _cylinder(rng, n, radius, half)


def _equalise(raw: np.ndarray) -> np.ndarray:
    """Rank-based equalisation onto 256 levels (reference_toolbox.md section 3.3)."""
    order = np.argsort(raw, kind="stable")
    values = np.empty(len(raw))
    values[order] = np.floor(256.0 * np.arange(len(raw)) / len(raw)) / 256.0
    return values


def _lidar_fov(points: np.ndarray) -> float:
    """``estimate_lidar_fov``: 0.2 m voxel centroids beyond 1 m, convex hull, widest pair."""
    from scipy.spatial import ConvexHull

    keys, inverse = np.unique(np.floor(points / 0.2).astype(np.int64), axis=0, return_inverse=True)
    centroids = np.zeros((len(keys), 3))
    np.add.at(centroids, inverse.reshape(-1), points)
    centroids /= np.bincount(inverse.reshape(-1))[:, None]
    centroids = centroids[np.linalg.norm(centroids, axis=1) >= 1.0]
    hull = centroids[ConvexHull(centroids).vertices]
    d = hull / np.linalg.norm(hull, axis=1, keepdims=True)
    return float(np.arccos(np.clip((d @ d.T).min(), -1.0, 1.0)))


def _reference_lidar_image(points, intensities, model, intrinsics, R_lidar_vcam, size):
    """``generate_lidar_image``: FoV cone, truncating projection, squared-range z-buffer."""
    width, height = size
    p = points @ R_lidar_vcam  # p_vcam = R_lidar_vcam^T p_lidar, row by row
    if model == "plumb_bob":
        fx, fy, cx, cy = intrinsics
        corner = math.atan(math.hypot(cx, cy) / fx)  # estimate_camera_fov: corner (0, 0)
        keep = p[:, 2] / np.linalg.norm(p, axis=1) >= math.cos(corner)
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.column_stack([fx * p[:, 0] / p[:, 2] + cx, fy * p[:, 1] / p[:, 2] + cy])
    else:  # equirectangular; its numeric FoV is 180 degrees: every point is inside
        b = p / np.linalg.norm(p, axis=1, keepdims=True)
        lat, lon = -np.arcsin(b[:, 1]), np.arctan2(b[:, 0], b[:, 2])
        uv = np.column_stack([width * (0.5 + lon / (2 * np.pi)), height * (0.5 - lat / np.pi)])
        keep = np.ones(len(p), bool)
    pixel = np.trunc(np.where(keep[:, None], uv, -1.0)).astype(np.int64)  # Vector2i cast
    keep &= (pixel >= 0).all(axis=1) & (pixel[:, 0] < width) & (pixel[:, 1] < height)
    rows = np.flatnonzero(keep)
    flat = pixel[rows, 1] * width + pixel[rows, 0]
    range2 = np.einsum("ij,ij->i", points[rows], points[rows])
    # per pixel the nearest point; of equal ranges the later one (it overwrites in cloud order)
    order = np.lexsort((-rows, range2, flat))
    first = order[np.r_[True, flat[order][1:] != flat[order][:-1]]]
    index = np.full(height * width, -1, dtype=np.int32)
    value = np.zeros(height * width)
    index[flat[first]] = rows[first]
    value[flat[first]] = intensities[rows[first]]
    return value.reshape(height, width), index.reshape(height, width)


def _superglue_matches(rng, camera, T_camera_lidar, points, index, n_good=150):
    """SuperGlue-like matches from the truth: whole-pixel keypoints in both images."""
    width = index.shape[1]
    filled = np.flatnonzero(index.reshape(-1) >= 0)
    chosen = rng.choice(filled, size=min(4 * n_good, len(filled)), replace=False)
    rows = index.reshape(-1)[chosen]
    p_camera = points[rows].astype(np.float64) @ T_camera_lidar[:3, :3].T + T_camera_lidar[:3, 3]
    uv, ok = camera.project(p_camera, in_image=True)
    chosen, uv = chosen[ok][:n_good], uv[ok][:n_good]
    kpts0 = np.floor(uv + 0.5)  # SuperPoint keypoints are whole pixels
    v1, u1 = np.divmod(chosen, width)
    kpts1 = np.column_stack([u1, v1]).astype(np.float64)
    matches = np.arange(len(kpts0))
    # a few LiDAR keypoints on empty pixels, a few wrong matches, a few unmatched ones
    empty = np.flatnonzero(index.reshape(-1) < 0)
    ve, ue = np.divmod(rng.choice(empty, size=5, replace=False), width)
    kpts1 = np.vstack([kpts1, np.column_stack([ue, ve])])
    matches = np.concatenate([matches, len(kpts0) + np.arange(5)])
    kpts0 = np.vstack([kpts0, np.floor(rng.uniform([0, 0], [camera.width, camera.height], (5, 2)))])
    wrong = rng.choice(len(matches) - 5, size=5, replace=False)
    matches[wrong] = rng.permutation(matches[wrong])
    extra = np.floor(rng.uniform([0, 0], [camera.width, camera.height], (10, 2)))
    kpts0 = np.vstack([kpts0, extra])
    matches = np.concatenate([matches, np.full(10, -1)])
    confidence = rng.uniform(0.2, 0.9, len(matches)).astype(np.float32)
    confidence[matches < 0] = 0.0
    return {
        "kpts0": kpts0.astype(np.float32).reshape(-1).tolist(),
        "kpts1": kpts1.astype(np.float32).reshape(-1).tolist(),
        "matches": matches.astype(np.int64).tolist(),
        "confidence": confidence.tolist(),
    }


def write_reference_workdir(
    path, *, lidar: str = "livox", seed: int = 0, n_points: int = 40_000, image_width: int = 320
) -> ReferenceWorkdir:
    """Write a reference-made work directory (module docstring) into ``path``.

    Parameters
    ----------
    path : str or os.PathLike
        The directory (created).
    lidar : {"livox", "spinning"}
        A 70-degree sector ahead (pinhole virtual camera) or all around (equirectangular).
    seed : int
        Scene, vertex order and matches.
    n_points : int
        Points of the dense cloud.
    image_width : int
        Of the camera image (4:3, 72 degrees wide).

    Returns
    -------
    ReferenceWorkdir
    """
    if lidar not in ("livox", "spinning"):
        raise ValueError(f"lidar must be 'livox' or 'spinning', got {lidar!r}")
    rng = np.random.default_rng(seed)
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    name = "rosbag2_2023_03_09-13_42_46"  # a ROS 2 bag folder's name
    points, raw = _scene(rng, lidar, n_points)
    order = rng.permutation(len(points))  # the voxel map's iteration order
    points, raw = points[order], raw[order]

    # the camera: looking along LiDAR +x (livox) or +y (spinning), a few cm off the origin
    w, h = image_width, image_width * 3 // 4
    f = 0.625 * w
    camera = create_camera(
        "plumb_bob", [f, f, (w - 1) / 2, (h - 1) / 2], [-0.05, 0.01, 0.0, 0.0, 0.0], w, h
    )
    yaw = 0.0 if lidar == "livox" else math.pi / 2
    c, s = math.cos(yaw), math.sin(yaw)
    R_lidar_camera = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ (R_LIDAR_VCAM_PINHOLE)
    T_camera_lidar = np.linalg.inv(make_T(R_lidar_camera, [0.05, -0.08, 0.03]))
    shot = render_view(
        camera, T_camera_lidar[:3, :3], points, raw, scale=1.0, fill_radius=3,
        t_vcam_lidar=T_camera_lidar[:3, 3],
    ).intensity  # fmt: skip
    cv2.imwrite(str(path / f"{name}.png"), cv2.equalizeHist(shot))

    # the dense cloud: equalised, stored as float32 by glk::save_ply_binary
    intensities = _equalise(raw)
    stored = np.column_stack([points, intensities]).astype("<f4")
    header = IRIDESCENCE_PLY_HEADER.format(n=len(stored)).encode("ascii")
    (path / f"{name}.ply").write_bytes(header + stored.tobytes())

    # the LiDAR image of the reference's virtual camera (from the double-precision cloud)
    fov = _lidar_fov(points)
    if fov < math.radians(150.0):
        size, model, R_lidar_vcam = (1024, 1024), "plumb_bob", R_LIDAR_VCAM_PINHOLE
        fx = 1024 / (2.0 * math.tan(fov / 2.0))
        vcam_intrinsics = [fx, fx, 512.0, 512.0]
    else:
        size, model, R_lidar_vcam = (1920, 960), "equirectangular", R_LIDAR_VCAM_EQUIRECTANGULAR
        vcam_intrinsics = [1920.0, 960.0]
    value, index = _reference_lidar_image(
        points, intensities, model, vcam_intrinsics, R_lidar_vcam, size
    )
    cv2.imwrite(str(path / f"{name}_lidar_intensities.png"), cv2.convertScaleAbs(value, None, 255))
    bgra = np.ascontiguousarray(index).view(np.uint8).reshape(*index.shape, 4)
    cv2.imwrite(str(path / f"{name}_lidar_indices.png"), bgra)

    # calib.json as nlohmann's dump(2): sorted keys, indent 2, no nbcalib section
    config = {
        "camera": {
            "camera_model": "plumb_bob",
            "distortion_coeffs": [float(x) for x in camera.distortion_coeffs],
            "intrinsics": [float(x) for x in camera.intrinsics],
        },
        "meta": {
            "bag_names": [name],
            "camera_info_topic": "/camera_info",
            "data_path": "/data/rosbags",
            "image_topic": "/image",
            "intensity_channel": "intensity",
            "points_topic": "/points",
        },
    }
    (path / "calib.json").write_text(json.dumps(config, indent=2, sort_keys=True) + "\n")

    # find_matches_superglue.py: json.dump without indent
    matches = _superglue_matches(rng, camera, T_camera_lidar, stored[:, :3], index)
    (path / f"{name}_matches.json").write_text(json.dumps(matches))
    return ReferenceWorkdir(
        path,
        name,
        camera,
        T_camera_lidar,
        stored[:, :3],
        stored[:, 3],
        model,
        vcam_intrinsics,
        R_lidar_vcam,
        index,
    )
