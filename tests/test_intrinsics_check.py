"""The cost over the focal length at a pose (nbcalib.report.intrinsics): the instrument of
issue 47's check sees a focal length that is off where the truth is exact."""

from __future__ import annotations

import numpy as np
import pytest

from nbcalib.camera import example_camera
from nbcalib.config import CalibrationConfig
from nbcalib.registration.pair import RegistrationPair
from nbcalib.report.intrinsics import _vertex, focal_scan, scaled_focal


def test_the_vertex_is_the_parabolas_and_the_lowest_sample_at_an_end():
    x = np.linspace(0.97, 1.03, 13)
    assert _vertex(x, (x - 1.0123) ** 2) == pytest.approx(1.0123, abs=1e-9)
    assert _vertex(x, x) == 0.97 and _vertex(x, -x) == 1.03


def _corner(camera, rng):
    """A textured corner (walls at 3-9 m and a floor) seen by ``camera``: points in the camera
    frame with their texture, and the image of the texture at each pixel's first hit."""

    def texture(p):
        return 0.5 + 0.25 * np.sin(2.3 * p[..., 0] + 1.1 * p[..., 2]) * np.cos(1.9 * p[..., 1])

    planes = [(2, 9.0), (1, 1.5), (0, -3.0), (0, 3.0)]
    h, w = camera.height, camera.width
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = camera.unproject(np.column_stack([u.ravel(), v.ravel()]))
    depth = np.full(len(rays), np.inf)
    for axis, offset in planes:
        with np.errstate(divide="ignore", invalid="ignore"):
            s = offset / rays[:, axis]
        depth = np.where((s > 0.1) & (s < depth), s, depth)
    hit = rays * np.where(np.isfinite(depth), depth, 0.0)[:, None]
    image = np.where(np.isfinite(depth), texture(hit), 0.0).reshape(h, w)
    points = []
    for axis, offset in planes:
        p = rng.uniform((-3.0, -2.0, 1.0), (3.0, 1.5, 9.0), (40000, 3))
        p[:, axis] = offset
        points.append(p)
    points = np.concatenate(points)
    return (255 * image).astype(np.uint8), points, texture(points)


@pytest.mark.parametrize("model", ["pinhole", "fisheye"])
def test_at_the_true_pose_the_cost_is_lowest_at_the_true_focal_length(model, rng):
    true = example_camera(model, 320, 240)
    image, points, intensities = _corner(true, rng)
    config = CalibrationConfig().refine
    for given_scale in (1.0, 1.02):
        given = scaled_focal(true, given_scale)
        pair = RegistrationPair(given, image, points, intensities, "corner")
        found = focal_scan([pair], np.eye(4), config)
        assert not found.at_edge
        assert found.best == pytest.approx(1.0 / given_scale, abs=0.003), found.to_dict()
