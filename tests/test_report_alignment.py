"""The report's alignment figure: the image at full width, zoomed where the structure is."""

from __future__ import annotations

import numpy as np
import pytest

from nbcalib.camera import example_camera
from tests.test_report import _png_pixels


def test_crop_windows_find_the_edge_points_on_image_edges():
    from nbcalib.report.figures import crop_windows

    image = np.full((150, 200), 100, dtype=np.uint8)
    image[:, 150:] = 200  # one strong vertical edge at column 150
    # edge points on the image's edge (rows 60-90) and points on flat image (no gradient)
    on_edge = np.column_stack([np.full(30, 149.5), np.linspace(60, 90, 30)])
    flat = np.column_stack([np.linspace(20, 60, 30), np.full(30, 40.0)])
    windows = crop_windows(np.vstack([on_edge, flat]), image, (40, 30), count=2)
    (left, top), second = windows[0], windows[1]
    assert left <= 149 < left + 40 and top <= 75 < top + 30
    # the second does not overlap the first
    assert abs(second[0] - left) >= 40 or abs(second[1] - top) >= 30


def test_alignment_draws_points_at_full_resolution_and_zoomed():
    pytest.importorskip("matplotlib")
    from nbcalib.report import figures as fg

    cam = example_camera("plumb_bob", 200, 150)
    image = np.full((150, 200), 100, dtype=np.uint8)
    image[:, 100:] = 200
    uv = np.column_stack([np.full(20, 100.0), np.linspace(50, 100, 20)])
    bearings = cam.unproject(uv)
    points = bearings / np.linalg.norm(bearings, axis=1, keepdims=True) * 5.0
    png = fg.alignment(cam, image, points, np.arange(20), np.eye(4), np.arange(20))
    pixels = _png_pixels(png)
    top = fg._MARGIN_PX + fg._TITLE_PX
    full = pixels[top : top + cam.height, fg._MARGIN_PX : fg._MARGIN_PX + cam.width]
    orange = np.array([255, 127, 14])
    # every point is an orange pixel at its own position in the full-resolution panel
    for c, r in np.floor(uv + 0.5).astype(int):
        np.testing.assert_array_equal(full[r, c], orange)
    assert np.count_nonzero(np.all(full == orange, axis=2)) == len(uv)
    # the zoomed crops below are CROP_ZOOM times the crop size and show the points enlarged
    crop_w = max(48, round(fg.CROP_SHARE * cam.width))
    zoom_top = 2 * fg._MARGIN_PX + 2 * fg._TITLE_PX + cam.height
    zoom = pixels[zoom_top : zoom_top + 4 * round(crop_w * 0.6), fg._MARGIN_PX :]
    assert np.count_nonzero(np.all(zoom == orange, axis=2)) > 4 * len(uv)
