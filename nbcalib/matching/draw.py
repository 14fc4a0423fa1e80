"""The matches drawn on a side-by-side picture (the reference's ``<name>_superglue.png``).

The camera image on the left, a LiDAR image resized to the camera image's size on the right,
one line per match coloured by ``turbo(confidence / max confidence)``. OpenCV only.

:func:`draw_matches` draws keypoint matches of two given images. :func:`draw_pair_matches`
draws one pair's matching result (``<name>_matches.png``) on the LiDAR image that was matched
(:func:`picture_matches`): with camera-shaped views, a view, each line ending at its 3-D point's
pixel there; the stored LiDAR image (a panorama, where the camera's matches would crowd into a
small patch) is drawn only when it was matched itself.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from nbcalib.matching.matches import Matches

__all__ = ["draw_matches", "draw_pair_matches", "picture_matches"]


def _to_bgr(image: np.ndarray) -> np.ndarray:
    import cv2

    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {image.dtype}")
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if image.ndim == 3 and image.shape[2] == 3:
        return np.ascontiguousarray(image[:, :, ::-1])  # nbcalib keeps colour as RGB
    raise ValueError(f"images must be (H, W) grey or (H, W, 3) RGB, got {image.shape}")


def draw_matches(
    camera_image: np.ndarray,
    lidar_image: np.ndarray,
    matches: Matches,
    *,
    show_keypoints: bool = True,
    thickness: int = 1,
) -> np.ndarray:
    """Draw matches between a camera image and a LiDAR image side by side.

    Parameters
    ----------
    camera_image : ndarray of shape (H, W) or (H, W, 3), uint8
        The camera image (grey, or RGB).
    lidar_image : ndarray of shape (h, w), uint8
        The LiDAR image; drawn resized to (H, W).
    matches : Matches
        Keypoints in the two images' own pixels.
    show_keypoints : bool, optional
        Also mark unmatched keypoints (small grey dots).
    thickness : int, optional
        Line thickness, pixels.

    Returns
    -------
    ndarray of shape (H, 2 W, 3), uint8
        The picture, **RGB** (write it with :func:`nbcalib.io.image.write_png`).
    """
    import cv2

    left = _to_bgr(camera_image)
    height, width = left.shape[:2]
    lidar = _to_bgr(lidar_image)
    lh, lw = lidar.shape[:2]
    right = cv2.resize(lidar, (width, height), interpolation=cv2.INTER_NEAREST)
    canvas = np.concatenate([left, right], axis=1)
    scale = np.array([width / lw, height / lh])

    def lidar_to_canvas(uv):
        # pixel centres at integers: resize maps u to (u + 0.5) * s - 0.5
        return (uv + 0.5) * scale - 0.5 + np.array([width, 0.0])

    shift = 4  # sub-pixel drawing: coordinates in 1/16 pixel
    factor = 1 << shift

    def fixed(uv):
        return np.round(uv * factor).astype(np.int64)

    if show_keypoints:
        for u, v in fixed(matches.kpts_camera):
            cv2.circle(
                canvas, (int(u), int(v)), 1 * factor, (160, 160, 160), -1, cv2.LINE_AA, shift
            )
        for u, v in fixed(lidar_to_canvas(matches.kpts_lidar)):
            cv2.circle(
                canvas, (int(u), int(v)), 1 * factor, (160, 160, 160), -1, cv2.LINE_AA, shift
            )
    uv0, uv1, confidence = matches.matched()
    if len(uv0):
        top = float(confidence.max())
        level = confidence / top if top > 0 else np.zeros_like(confidence)
        lut = cv2.applyColorMap(np.arange(256, dtype=np.uint8)[:, None], cv2.COLORMAP_TURBO)
        colours = lut[np.clip(np.round(level * 255), 0, 255).astype(int), 0]
        p0 = fixed(uv0)
        p1 = fixed(lidar_to_canvas(uv1))
        # weakest first, so that the strongest matches are drawn on top
        for i in np.argsort(level, kind="stable"):
            colour = tuple(int(c) for c in colours[i])
            a, b = (int(p0[i, 0]), int(p0[i, 1])), (int(p1[i, 0]), int(p1[i, 1]))
            cv2.line(canvas, a, b, colour, thickness, cv2.LINE_AA, shift)
            cv2.circle(canvas, a, 2 * factor, colour, -1, cv2.LINE_AA, shift)
            cv2.circle(canvas, b, 2 * factor, colour, -1, cv2.LINE_AA, shift)
    return np.ascontiguousarray(canvas[:, :, ::-1])


def picture_matches(found, lidar_image: np.ndarray) -> tuple[np.ndarray, Matches]:
    """The LiDAR image to draw one pair's matching result on, and the matches in its pixels.

    Parameters
    ----------
    found : PairMatches
        One pair's matching result (:func:`~nbcalib.matching.find.find_correspondences`).
    lidar_image : ndarray of shape (h, w), uint8
        The pair's stored LiDAR image.

    Returns
    -------
    image : ndarray, uint8
        With camera-shaped views (``found.views``), the kept view that shows the most of the
        kept correspondences; else ``lidar_image``.
    matches : Matches
        With views, every kept correspondence whose 3-D point projects into that view, matched
        to its point's pixel there (the others are not drawn); else ``found.matches``: the
        matches with ``lidar_image`` at the pixels of their points.
    """
    views = found.views
    if views is None or not views.pooled:
        return np.asarray(lidar_image), found.matches
    from nbcalib.transforms import transform_points

    corr = found.correspondences
    best = None
    for k in views.pooled:
        view = views.views[k].view
        points = transform_points(view.T_vcam_lidar, corr.points_lidar)
        uv, shown = view.camera.project(points, in_image=True)
        if best is None or np.count_nonzero(shown) > np.count_nonzero(best[2]):
            best = (view, uv, shown)
    view, uv, shown = best
    n = int(np.count_nonzero(shown))
    matches = Matches(
        corr.uv_camera[shown],
        uv[shown],
        np.arange(n, dtype=np.int64),
        corr.weights[shown],
        matcher=found.matcher,
    )
    return view.intensity, matches


def draw_pair_matches(
    camera_image: np.ndarray, found, lidar_image: np.ndarray, *, max_lines: int = 200
) -> np.ndarray:
    """Draw one pair's matching result (``<name>_matches.png``) on the LiDAR image it matched.

    Parameters
    ----------
    camera_image : ndarray of shape (H, W), uint8
        The pair's camera image.
    found : PairMatches
        Its matching result.
    lidar_image : ndarray of shape (h, w), uint8
        Its stored LiDAR image (drawn when no views were matched).
    max_lines : int, optional
        Draw at most this many matches, evenly spread over their order (whatever their
        confidence), so that the images stay visible.

    Returns
    -------
    ndarray of shape (H, 2 W, 3), uint8
        RGB (:func:`draw_matches` of :func:`picture_matches`).
    """
    picture, matches = picture_matches(found, lidar_image)
    if matches.num_matches > max_lines:
        matched = np.flatnonzero(matches.matches >= 0)
        keep = matched[np.linspace(0, len(matched) - 1, max_lines).round().astype(int)]
        matches = replace(
            matches,
            kpts_camera=matches.kpts_camera[keep],
            matches=matches.matches[keep],
            confidence=matches.confidence[keep],
        )
    return draw_matches(camera_image, picture, matches, show_keypoints=False)
