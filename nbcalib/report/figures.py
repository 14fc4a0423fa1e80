"""PNG figures of the quality report (matplotlib, Agg, no pyplot state).

Each function returns the PNG bytes of one figure; :mod:`nbcalib.report.html` writes them. The
caller checks that matplotlib is installed (``nbcalib.errors.require("matplotlib", "viz")``).
"""

from __future__ import annotations

import io
import math

import numpy as np

from nbcalib.camera import CameraModel
from nbcalib.report.quality import AXIS_NAMES, Quality

__all__ = ["edge_overlay", "lidar_edge_points", "nid_curves", "overlays", "pairs_and_uncertainty"]

#: Points drawn per overlay panel at most (a random subset beyond that).
MAX_DRAWN_POINTS = 40000


def _figure(width_in: float, height_in: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), dpi=100, layout="constrained")


def _png(fig) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def _project_visible(camera: CameraModel, T_camera_lidar, points_lidar, keep):
    """Pixel positions (M, 2) and camera-frame depths (M,) of the points ``keep``."""
    points = np.asarray(points_lidar, dtype=np.float64)[keep]
    p_camera = points @ T_camera_lidar[:3, :3].T + T_camera_lidar[:3, 3]
    uv, valid = camera.project(p_camera, in_image=True)
    return uv[valid], np.linalg.norm(p_camera[valid], axis=1), np.flatnonzero(valid)


def _subsample(n: int, rng: np.random.Generator) -> np.ndarray:
    if n <= MAX_DRAWN_POINTS:
        return np.arange(n)
    return np.sort(rng.choice(n, MAX_DRAWN_POINTS, replace=False))


def overlays(
    camera: CameraModel,
    image: np.ndarray,
    points_lidar: np.ndarray,
    intensities: np.ndarray,
    poses: list[tuple[str, np.ndarray, np.ndarray]],
) -> bytes:
    """LiDAR points on the image, coloured by depth and by intensity, one row per pose.

    Parameters
    ----------
    camera : CameraModel
    image : ndarray of shape (H, W), uint8
        Grey camera image.
    points_lidar : ndarray of shape (N, 3), float64
        Dense cloud, LiDAR frame, metres.
    intensities : ndarray of shape (N,), float64
        Equalised intensities in [0, 1].
    poses : list of (title, T_camera_lidar (4, 4), visible indices (M,))
        E.g. the initial guess and the result, with the points visible from each.

    Returns
    -------
    bytes
        PNG.
    """
    rng = np.random.default_rng(0)
    aspect = camera.height / camera.width
    fig = _figure(11.0, 0.5 + 5.5 * aspect * len(poses))
    axes = fig.subplots(len(poses), 2, squeeze=False)
    for row, (title, T, keep) in enumerate(poses):
        uv, depth, valid = _project_visible(camera, T, points_lidar, keep)
        values = np.asarray(intensities)[keep][valid]
        pick = _subsample(len(uv), rng)
        for col, (colour, cmap, label) in enumerate(
            [(depth, "turbo", "range (m)"), (values, "viridis", "intensity")]
        ):
            ax = axes[row, col]
            ax.imshow(image, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
            if len(pick):
                hi = float(np.percentile(colour[pick], 98)) if col == 0 else 1.0
                sc = ax.scatter(
                    uv[pick, 0],
                    uv[pick, 1],
                    c=colour[pick],
                    s=2.0 if len(pick) < 20000 else 0.6,
                    cmap=cmap,
                    vmin=0.0,
                    vmax=max(hi, 1e-6),
                    linewidths=0,
                )
                fig.colorbar(sc, ax=ax, shrink=0.8, label=label)
            ax.set_title(f"{title}: {label.split()[0]} ({len(uv)} points)", fontsize=9)
            ax.set_xlim(-0.5, camera.width - 0.5)
            ax.set_ylim(camera.height - 0.5, -0.5)
            ax.set_axis_off()
    return _png(fig)


def lidar_edge_points(
    lidar_intensity: np.ndarray, lidar_index: np.ndarray, points_lidar: np.ndarray
) -> np.ndarray:
    """Indices of cloud points on intensity or depth edges of the LiDAR image.

    Parameters
    ----------
    lidar_intensity : ndarray of shape (H', W'), uint8
        The virtual-camera LiDAR image.
    lidar_index : ndarray of shape (H', W'), int32
        Cloud row shown by each pixel, -1 where empty.
    points_lidar : ndarray of shape (N, 3), float64

    Returns
    -------
    ndarray of shape (M,), int64
        Unique point indices: Canny edges of the intensity image, and pixels whose range differs
        by more than 10 % from a filled 4-neighbour.

    Notes
    -----
    A sparse LiDAR image (a Livox rosette, a 16-beam LiDAR) is mostly empty pixels, and Canny
    on it marks every point against its empty surroundings. The intensities are therefore
    spread into the gaps first (a normalised convolution: blurred values over blurred
    coverage), and only the coverage's filled pixels on the smooth image's edges count.
    """
    import cv2

    index = np.asarray(lidar_index)
    filled = index >= 0
    ranges = np.zeros(index.shape)
    ranges[filled] = np.linalg.norm(np.asarray(points_lidar)[index[filled]], axis=1)
    values = np.where(filled, np.asarray(lidar_intensity, dtype=np.float64), 0.0)
    # the blur reaches across the typical gap: sigma from the fill fraction (1 px when dense)
    sigma = max(1.0, 0.5 / math.sqrt(max(float(filled.mean()), 1e-3)))
    coverage = cv2.GaussianBlur(filled.astype(np.float64), (0, 0), sigma)
    smooth = cv2.GaussianBlur(values, (0, 0), sigma) / np.maximum(coverage, 1e-6)
    smooth = np.clip(np.where(coverage > 0.05, smooth, 0.0), 0, 255).astype(np.uint8)
    edges = cv2.Canny(smooth, 60, 160) > 0
    for axis in (0, 1):
        a = np.take(ranges, np.arange(ranges.shape[axis] - 1), axis=axis)
        b = np.take(ranges, np.arange(1, ranges.shape[axis]), axis=axis)
        fa = np.take(filled, np.arange(filled.shape[axis] - 1), axis=axis)
        fb = np.take(filled, np.arange(1, filled.shape[axis]), axis=axis)
        jump = fa & fb & (np.abs(a - b) > 0.1 * np.minimum(a, b))
        near_a = jump & (a <= b)  # mark the nearer side (the occluding contour)
        near_b = jump & (b < a)
        pad = [(0, 0), (0, 0)]
        pad[axis] = (0, 1)
        edges |= np.pad(near_a, pad)
        pad[axis] = (1, 0)
        edges |= np.pad(near_b, pad)
    return np.unique(index[edges & filled]).astype(np.int64)


def edge_overlay(camera: CameraModel, image, points_lidar, edge_points, poses) -> bytes:
    """Image edges (grey) against projected LiDAR edge points (orange), one panel per pose.

    ``camera``, ``image``, ``points_lidar`` and ``poses`` are as for :func:`overlays`;
    ``edge_points`` (ndarray of shape (M,), int64) are rows of ``points_lidar`` from
    :func:`lidar_edge_points`. Returns the PNG's bytes.
    """
    import cv2

    blurred = cv2.GaussianBlur(np.ascontiguousarray(image, dtype=np.uint8), (5, 5), 1.2)
    image_edges = cv2.Canny(blurred, 40, 120) > 0
    rng = np.random.default_rng(0)
    aspect = camera.height / camera.width
    fig = _figure(5.5 * len(poses), 0.6 + 5.5 * aspect)
    axes = fig.subplots(1, len(poses), squeeze=False)[0]
    for ax, (title, T, keep) in zip(axes, poses):
        on_edge = np.intersect1d(keep, edge_points, assume_unique=False)
        uv, _, _ = _project_visible(camera, T, points_lidar, on_edge)
        pick = _subsample(len(uv), rng)
        ax.imshow(image_edges, cmap="gray", vmin=0, vmax=3, interpolation="nearest")
        ax.scatter(uv[pick, 0], uv[pick, 1], s=1.5, c="tab:orange", linewidths=0)
        ax.set_title(f"{title}: image edges (grey), LiDAR edges (orange)", fontsize=9)
        ax.set_xlim(-0.5, camera.width - 0.5)
        ax.set_ylim(camera.height - 0.5, -0.5)
        ax.set_axis_off()
    return _png(fig)


def nid_curves(quality: Quality) -> bytes:
    """The summed NID along each of the six axes around the result."""
    fig = _figure(11.0, 5.5)
    axes = fig.subplots(2, 3, sharey=True)
    centre = quality.curve_values.shape[1] // 2
    for a, ax in enumerate(axes.ravel()):
        scale, unit = (100.0, "cm") if a < 3 else (math.degrees(1.0), "deg")
        x = quality.curve_offsets[a] * scale
        ax.plot(x, quality.curve_values[a], "o-", ms=3)
        ax.axvline(0.0, color="k", lw=0.6)
        ax.plot([0.0], [quality.curve_values[a, centre]], "rs", ms=5)
        half = quality.uncertainty.get("translation_cm" if a < 3 else "rotation_deg")
        if half is not None:
            h = half[a % 3]
            if h < abs(x).max():
                ax.axvspan(-h, h, color="tab:green", alpha=0.15, lw=0)
        ax.set_xlabel(f"{AXIS_NAMES[a]} ({unit}, camera axes)")
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("summed NID")
    axes[1, 0].set_ylabel("summed NID")
    fig.suptitle(
        "NID around the result (red); green: stated "
        f"{100 * quality.uncertainty.get('confidence', 0.95):.0f} % interval",
        fontsize=10,
    )
    return _png(fig)


def pairs_and_uncertainty(quality: Quality) -> bytes:
    """Per-pair NID and visible points; per-axis interval with each pair's own optimum."""
    fig = _figure(11.0, 3.8)
    ax_pairs, ax_t, ax_r = fig.subplots(1, 3)
    k = np.arange(len(quality.names))
    ax_pairs.bar(k, quality.nid_per_pair, color="tab:blue")
    for i, n in enumerate(quality.visible_points):
        ax_pairs.text(i, quality.nid_per_pair[i], f"{n}", ha="center", va="bottom", fontsize=7)
    ax_pairs.set_xticks(k, [n[:12] for n in quality.names], rotation=45, fontsize=7)
    ax_pairs.set_ylim(0.0, 1.0)
    ax_pairs.set_ylabel("NID (number: visible points)")
    ax_pairs.set_title("per pair", fontsize=9)
    u = quality.uncertainty
    for ax, key, sl, scale, unit in (
        (ax_t, "translation_cm", slice(0, 3), 100.0, "cm"),
        (ax_r, "rotation_deg", slice(3, 6), math.degrees(1.0), "deg"),
    ):
        half = np.asarray(u[key])
        x = np.arange(3)
        ax.errorbar(x, np.zeros(3), yerr=half, fmt="s", color="k", capsize=6)
        if quality.pair_offsets is not None:
            for j, off in enumerate(quality.pair_offsets):
                ax.plot(x + 0.08 * (j + 1), off[sl] * scale, "o", ms=4, label=quality.names[j])
            ax.legend(fontsize=6)
        ax.set_xticks(x, AXIS_NAMES[sl])
        ax.set_ylabel(unit)
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_title(
            f"{100 * u['confidence']:.0f} % interval"
            + (" and per-pair optima" if quality.pair_offsets is not None else ""),
            fontsize=9,
        )
        ax.grid(alpha=0.3)
    return _png(fig)
