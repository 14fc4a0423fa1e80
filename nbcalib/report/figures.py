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

__all__ = [
    "alignment",
    "crop_windows",
    "edge_overlay",
    "lidar_edge_points",
    "nid_curves",
    "overlays",
    "pairs_and_uncertainty",
    "rasterise_points",
]

#: Points drawn per overlay panel at most (a random subset beyond that).
MAX_DRAWN_POINTS = 40000

#: Resolution of every figure (pixels per inch); the layouts below are in pixels.
DPI = 100

#: Width (pixels) of the camera image in each panel of :func:`overlays` and of
#: :func:`edge_overlay`. The points are drawn at this resolution, so they stay a pixel or two
#: wide whatever the camera's resolution.
OVERLAY_PANEL_WIDTH = 440
EDGE_PANEL_WIDTH = 540

#: Grey level (0-255) of the image edges in :func:`edge_overlay`.
EDGE_GREY = 140

#: :func:`alignment`: the widest full-width panel (pixels; the camera's own width when
#: narrower), the crops' share of the image width and their magnification.
ALIGNMENT_WIDTH = 1600
CROP_SHARE = 0.14
CROP_ZOOM = 4

_TITLE_PX = 26  # space above each panel for its title
_MARGIN_PX = 10
_COLORBAR_PX = (8, 14, 72)  # gap to the panel, bar width, room for the ticks and the label


def _figure(width_in: float, height_in: float):
    from matplotlib.figure import Figure

    return Figure(figsize=(width_in, height_in), dpi=DPI, layout="constrained")


def _png(fig, compress_level: int = 6) -> bytes:
    """The figure as PNG bytes.

    ``compress_level`` is zlib's: the photo-like overlays take 3, half the time of 6 for the
    same size.
    """
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", pil_kwargs={"compress_level": compress_level})
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


def _dot_size(n_points: int) -> int:
    """Side (display pixels) of each drawn point: bigger when there are few."""
    return 1 if n_points >= 20000 else 2 if n_points >= 2000 else 3


def rasterise_points(
    image_rgb: np.ndarray,
    uv: np.ndarray,
    colours: np.ndarray,
    depth: np.ndarray | None = None,
    size: int = 1,
) -> np.ndarray:
    """Draw points as small opaque dots into a copy of an RGB image, nearer over farther.

    Parameters
    ----------
    image_rgb : ndarray of shape (H, W, 3), uint8
        The background.
    uv : ndarray of shape (N, 2), float
        Pixel positions in ``image_rgb`` (u = column, v = row; pixel centres at integers).
    colours : ndarray of shape (N, 3) or (3,), uint8
        Each point's colour, or one colour for all.
    depth : ndarray of shape (N,), float, optional
        Distance from the camera; where dots overlap, the nearest is drawn. Without it, the
        later point in ``uv`` wins.
    size : int, optional
        Side of each dot in pixels: 1 is the pixel the point falls in, 2 the 2 x 2 block whose
        centre is nearest to the point, 3 the 3 x 3 block around it; from 4 on, the corners
        farther than ``size / 2`` from the centre are left out (a disc).

    Returns
    -------
    ndarray of shape (H, W, 3), uint8
        The image with the dots; pixels no dot covers are ``image_rgb``'s.
    """
    out = np.array(image_rgb, dtype=np.uint8, copy=True)
    h, w = out.shape[:2]
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    finite = np.all(np.isfinite(uv), axis=1)
    if size < 1 or not finite.any():
        return out
    colours = np.asarray(colours, dtype=np.uint8)[..., :3]
    colours = np.broadcast_to(colours, (len(uv), 3))[finite]
    if depth is None:
        depth = -np.arange(len(uv), dtype=np.float64)  # later points "nearer"
    depth = np.asarray(depth, dtype=np.float64)[finite]
    uv = uv[finite]
    # the dot's top-left pixel, so that the size x size block is centred nearest to the point
    corner = np.floor(uv - (size - 1) / 2.0 + 0.5).astype(np.int64)
    dy, dx = np.mgrid[0:size, 0:size].reshape(2, -1)
    in_dot = (dx - (size - 1) / 2.0) ** 2 + (dy - (size - 1) / 2.0) ** 2 <= (size / 2.0) ** 2
    dx, dy = dx[in_dot], dy[in_dot]  # all of the block up to 3 x 3
    cols = (corner[:, 0:1] + dx).ravel()
    rows = (corner[:, 1:2] + dy).ravel()
    point = np.repeat(np.arange(len(uv)), len(dx))
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
    pixel, point = rows[inside] * w + cols[inside], point[inside]
    # per pixel, the nearest point: sort by pixel, then depth; keep each pixel's first
    order = np.lexsort((depth[point], pixel))
    pixel, point = pixel[order], point[order]
    first = np.ones(len(pixel), dtype=bool)
    first[1:] = pixel[1:] != pixel[:-1]
    out.reshape(-1, 3)[pixel[first]] = colours[point[first]]
    return out


def _resized_rgb(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` (grey or colour, uint8) as an RGB image of ``width`` x ``height`` pixels."""
    import cv2

    image = np.ascontiguousarray(image, dtype=np.uint8)
    if image.ndim == 3:
        image = image[..., :3] if image.shape[2] >= 3 else image[..., 0]
    if (image.shape[1], image.shape[0]) != (width, height):
        shrink = width < image.shape[1]
        image = cv2.resize(
            image,
            (width, height),
            interpolation=cv2.INTER_AREA if shrink else cv2.INTER_NEAREST,
        )
    return np.repeat(image[..., None], 3, axis=2) if image.ndim == 2 else image


def _to_panel(uv: np.ndarray, scale: float) -> np.ndarray:
    """Camera pixel positions to positions in a panel ``scale`` times the image's size."""
    return (np.asarray(uv, dtype=np.float64) + 0.5) * scale - 0.5


def _show(fig, rect_px, fig_size_px, picture: np.ndarray, title: str):
    """Show ``picture`` pixel for pixel in a new axes at ``rect_px``, titled ``title``.

    ``rect_px`` is (left, top, width, height) in pixels from the figure's top left; its size
    is the picture's.
    """
    ax = fig.add_axes(_fraction(rect_px, fig_size_px))
    ax.imshow(picture, interpolation="nearest", aspect="auto")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()
    return ax


def _fraction(rect_px, fig_size_px):
    """Turn (left, top, width, height) in pixels from the top left into figure fractions.

    Returns matplotlib's (left, bottom, width, height).
    """
    left, top, width, height = rect_px
    fig_w, fig_h = fig_size_px
    return (left / fig_w, 1.0 - (top + height) / fig_h, width / fig_w, height / fig_h)


def _fixed_figure(width_px: int, height_px: int):
    """A figure without a layout engine: the functions place every axes themselves."""
    from matplotlib.figure import Figure

    return Figure(figsize=(width_px / DPI, height_px / DPI), dpi=DPI)


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

    Notes
    -----
    The points (a random subset of :data:`MAX_DRAWN_POINTS` at most) are drawn into each
    panel's picture at the panel's resolution by :func:`rasterise_points`, nearer points over
    farther ones: one image per panel instead of tens of thousands of markers.
    """
    import matplotlib as mpl

    rng = np.random.default_rng(0)
    panel_w = OVERLAY_PANEL_WIDTH
    panel_h = max(1, round(panel_w * camera.height / camera.width))
    scale = panel_w / camera.width
    background = _resized_rgb(image, panel_w, panel_h)
    gap, bar_w, bar_room = _COLORBAR_PX
    column_w = panel_w + gap + bar_w + bar_room
    row_h = _TITLE_PX + panel_h
    fig_size = (2 * column_w + 3 * _MARGIN_PX, len(poses) * row_h + (len(poses) + 1) * _MARGIN_PX)
    fig = _fixed_figure(*fig_size)
    for row, (title, T, keep) in enumerate(poses):
        uv, depth, valid = _project_visible(camera, T, points_lidar, keep)
        values = np.asarray(intensities)[keep][valid]
        pick = _subsample(len(uv), rng)
        uv_panel = _to_panel(uv[pick], scale)
        top = _MARGIN_PX + row * (row_h + _MARGIN_PX) + _TITLE_PX
        for col, (colour, cmap_name, label) in enumerate(
            [(depth, "turbo", "range (m)"), (values, "viridis", "intensity")]
        ):
            left = _MARGIN_PX + col * (column_w + _MARGIN_PX)
            picture = background
            if len(pick):
                hi = float(np.percentile(colour[pick], 98)) if col == 0 else 1.0
                norm = mpl.colors.Normalize(vmin=0.0, vmax=max(hi, 1e-6))
                cmap = mpl.colormaps[cmap_name]
                rgb = cmap(norm(colour[pick]), bytes=True)[:, :3]
                picture = rasterise_points(
                    background, uv_panel, rgb, depth[pick], _dot_size(len(pick))
                )
            _show(
                fig,
                (left, top, panel_w, panel_h),
                fig_size,
                picture,
                f"{title}: {label.split()[0]} ({len(uv)} points)",
            )
            if len(pick):
                bar_h = round(0.8 * panel_h)
                cax = fig.add_axes(
                    _fraction(
                        (left + panel_w + gap, top + (panel_h - bar_h) // 2, bar_w, bar_h),
                        fig_size,
                    )
                )
                mappable = mpl.cm.ScalarMappable(norm=norm, cmap=cmap)
                fig.colorbar(mappable, cax=cax, label=label)
    return _png(fig, compress_level=3)


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
    from matplotlib.colors import to_rgb

    blurred = cv2.GaussianBlur(np.ascontiguousarray(image, dtype=np.uint8), (5, 5), 1.2)
    image_edges = cv2.Canny(blurred, 40, 120)  # 0 or 255
    panel_w = EDGE_PANEL_WIDTH
    panel_h = max(1, round(panel_w * camera.height / camera.width))
    scale = panel_w / camera.width
    # shrunk by area, a one-pixel edge becomes a fainter line: brighten it back by 1 / scale
    shrunk = _resized_rgb(image_edges, panel_w, panel_h).astype(np.float64)
    background = np.round(np.minimum(1.0, shrunk / 255.0 / min(scale, 1.0)) * EDGE_GREY)
    background = background.astype(np.uint8)
    orange = np.round(255 * np.array(to_rgb("tab:orange"))).astype(np.uint8)
    dot = 2 if scale <= 1.0 else math.ceil(scale) + 1  # wider than an enlarged edge pixel
    rng = np.random.default_rng(0)
    fig_size = (
        len(poses) * (panel_w + _MARGIN_PX) + _MARGIN_PX,
        _TITLE_PX + panel_h + 2 * _MARGIN_PX,
    )
    fig = _fixed_figure(*fig_size)
    is_edge = np.zeros(len(points_lidar), dtype=bool)
    is_edge[edge_points] = True
    for k, (title, T, keep) in enumerate(poses):
        on_edge = np.sort(keep[is_edge[keep]])  # np.intersect1d's answer, without its sorts
        uv, depth, _ = _project_visible(camera, T, points_lidar, on_edge)
        pick = _subsample(len(uv), rng)
        picture = rasterise_points(background, _to_panel(uv[pick], scale), orange, depth[pick], dot)
        _show(
            fig,
            (_MARGIN_PX + k * (panel_w + _MARGIN_PX), _MARGIN_PX + _TITLE_PX, panel_w, panel_h),
            fig_size,
            picture,
            f"{title}: image edges (grey), LiDAR edges (orange)",
        )
    return _png(fig, compress_level=3)


def crop_windows(uv: np.ndarray, image: np.ndarray, size: tuple[int, int], count: int = 2):
    """Where the structure is: windows with the most projected edge points on image edges.

    Each LiDAR edge point ``uv`` (camera pixels) scores the image's gradient magnitude around
    it; a window's score is the sum over its points (a box filter of the score map), and the
    ``count`` best windows that do not overlap are returned, best first.

    Returns
    -------
    list of (left, top)
        Window corners, pixels, each window ``size`` = (width, height) inside the image.
    """
    import cv2

    h, w = image.shape[:2]
    cw, ch = min(size[0], w), min(size[1], h)
    grey = cv2.GaussianBlur(np.asarray(image, dtype=np.float32), (0, 0), 1.0)
    gradient = np.hypot(cv2.Sobel(grey, cv2.CV_32F, 1, 0), cv2.Sobel(grey, cv2.CV_32F, 0, 1))
    col = np.clip(np.floor(uv[:, 0] + 0.5).astype(np.int64), 0, w - 1)
    row = np.clip(np.floor(uv[:, 1] + 0.5).astype(np.int64), 0, h - 1)
    score = np.zeros((h, w), dtype=np.float64)
    np.add.at(score, (row, col), gradient[row, col])
    integral = np.pad(score, ((1, 0), (1, 0))).cumsum(0).cumsum(1)
    sums = (
        integral[ch:, cw:] - integral[:-ch, cw:] - integral[ch:, :-cw] + integral[:-ch, :-cw]
    )  # sums[t, l]: the window with top-left (l, t)
    windows = []
    for _ in range(count):
        t, l = np.unravel_index(int(np.argmax(sums)), sums.shape)
        if sums[t, l] <= 0 and windows:
            break
        windows.append((int(l), int(t)))
        # no overlap with the next ones
        sums[max(0, t - ch + 1) : t + ch, max(0, l - cw + 1) : l + cw] = -1.0
    return windows


def alignment(camera: CameraModel, image, points_lidar, edge_points, T, keep) -> bytes:
    """The result on the camera image at full width, and zoomed crops where the structure is.

    LiDAR edge points (:func:`lidar_edge_points`) visible from ``T`` (``keep``) are drawn in
    orange on the grey camera image, a pixel each at the image's own resolution (up to
    :data:`ALIGNMENT_WIDTH`), then :data:`CROP_ZOOM` times enlarged in the two windows of
    :func:`crop_windows`: there a misalignment of one or two image pixels is four to eight
    screen pixels between the orange points and the image's own edges.
    """
    from matplotlib.colors import to_rgb

    image = np.ascontiguousarray(image, dtype=np.uint8)
    orange = np.round(255 * np.array(to_rgb("tab:orange"))).astype(np.uint8)
    is_edge = np.zeros(len(points_lidar), dtype=bool)
    is_edge[edge_points] = True
    on_edge = np.sort(keep[is_edge[keep]])
    uv, depth, _ = _project_visible(camera, T, points_lidar, on_edge)
    full_w = min(camera.width, ALIGNMENT_WIDTH)
    full_h = max(1, round(full_w * camera.height / camera.width))
    scale = full_w / camera.width
    full = rasterise_points(
        _resized_rgb(image, full_w, full_h), _to_panel(uv, scale), orange, depth, 1
    )
    crop_w = max(48, round(CROP_SHARE * camera.width))
    crop_h = max(32, round(crop_w * 0.6))
    windows = crop_windows(uv, image, (crop_w, crop_h)) if len(uv) else []
    zoom_w, zoom_h = crop_w * CROP_ZOOM, crop_h * CROP_ZOOM
    row_h = _TITLE_PX + zoom_h if windows else 0
    fig_w = max(full_w, len(windows) * (zoom_w + _MARGIN_PX) - _MARGIN_PX) + 2 * _MARGIN_PX
    fig_size = (fig_w, _TITLE_PX + full_h + 2 * _MARGIN_PX + row_h + (_MARGIN_PX if windows else 0))
    fig = _fixed_figure(*fig_size)
    _show(
        fig,
        (_MARGIN_PX, _MARGIN_PX + _TITLE_PX, full_w, full_h),
        fig_size,
        full,
        f"result: LiDAR edges (orange) on the image, {full_w} px wide "
        f"({'full resolution' if scale == 1.0 else f'{scale:.2f} x'})",
    )
    top = 2 * _MARGIN_PX + 2 * _TITLE_PX + full_h
    for k, (left, upper) in enumerate(windows):
        crop = image[upper : upper + crop_h, left : left + crop_w]
        inside = (
            (uv[:, 0] >= left - 1) & (uv[:, 0] < left + crop_w)
            & (uv[:, 1] >= upper - 1) & (uv[:, 1] < upper + crop_h)
        )  # fmt: skip
        local = uv[inside] - np.array([left, upper])
        picture = rasterise_points(
            _resized_rgb(crop, zoom_w, zoom_h),
            _to_panel(local, CROP_ZOOM),
            orange,
            depth[inside],
            CROP_ZOOM // 2 + 1,
        )
        _show(
            fig,
            (_MARGIN_PX + k * (zoom_w + _MARGIN_PX), top, zoom_w, zoom_h),
            fig_size,
            picture,
            f"{CROP_ZOOM} x: pixels {left}-{left + crop_w}, {upper}-{upper + crop_h}",
        )
    return _png(fig, compress_level=3)


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
