"""The structure channel: depth-edge scores, image edges, and the structure term of the cost."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.camera import example_camera
from nbcalib.registration.nid import NIDCost
from nbcalib.registration.refine import RefineConfig, RegistrationPair, build_cost
from nbcalib.registration.structure import depth_edge_scores, image_edges


def ring_scan(ranges, elevations_deg=(-2.0, 0.0, 2.0), step_deg=0.5):
    """Rings of points at the given range per azimuth (same ranges on every ring)."""
    az = np.radians(np.arange(len(ranges)) * step_deg)
    rows = []
    for el in np.radians(elevations_deg):
        rows.append(
            np.column_stack(
                [
                    ranges * np.cos(el) * np.cos(az),
                    ranges * np.cos(el) * np.sin(az),
                    ranges * np.sin(el),
                ]
            )
        )
    return np.vstack(rows)


def test_scores_mark_the_near_side_of_a_range_jump():
    ranges = np.full(60, 10.0)
    ranges[30:] = 5.0  # an object in front from azimuth 15 deg on
    pts = ring_scan(ranges)
    s = depth_edge_scores(pts, neighbours=3, clip=2.0)
    per_ring = s.reshape(3, 60)
    # the first near point of each ring sees 5 m behind it: clipped to 1; the far side is 0
    assert_allclose(per_ring[:, 30], 1.0)
    assert_allclose(per_ring[:, 29], 0.0)
    # flat parts score 0
    assert per_ring[:, 1:28].max() < 1e-6 and per_ring[:, 32:59].max() < 1e-6


def test_scores_match_a_loop_over_ring_neighbours():
    rng = np.random.default_rng(3)
    ranges = 8.0 + np.cumsum(rng.normal(0, 0.3, 80))
    pts = ring_scan(ranges, elevations_deg=(0.0,))
    s = depth_edge_scores(pts, neighbours=3, clip=1.5)
    r = np.linalg.norm(pts, axis=1)
    for i in range(1, 79):  # the reference: both azimuth neighbours of the ring
        jump = max(r[i - 1] - r[i], r[i + 1] - r[i], 0.0)
        assert s[i] == pytest.approx(np.sqrt(min(jump, 1.5) / 1.5), abs=1e-12)


def test_ground_rings_are_not_edges():
    # a flat ground seen by rings 1 degree apart: the next ring lies metres farther, but along
    # the elevation axis, which the neighbour search stretches away
    az = np.radians(np.arange(0, 40, 0.2))
    rows = []
    for el in np.radians(np.arange(-15.0, -5.0, 1.0)):
        r = 1.7 / np.sin(-el)
        rows.append(
            np.column_stack(
                [r * np.cos(el) * np.cos(az), r * np.cos(el) * np.sin(az), np.full(az.size, -1.7)]
            )
        )
    s = depth_edge_scores(np.vstack(rows))
    assert np.median(s) < 0.05


def test_bad_points_score_zero_and_shapes_are_checked():
    pts = np.array([[np.nan, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0.01, 0]])
    s = depth_edge_scores(pts)
    assert s.shape == (4,) and s[0] == 0 and s[1] == 0
    with pytest.raises(ValueError):
        depth_edge_scores(np.zeros((3, 2)))


def test_image_edges_peak_on_a_step():
    img = np.zeros((40, 60), dtype=np.uint8)
    img[:, 30:] = 200
    e = image_edges(img)
    assert e.dtype == np.uint8 and e.shape == img.shape
    assert e[20, 29:31].min() == 255 and e[20, 5] == 0 and e[20, 55] == 0
    assert not image_edges(np.full((10, 10), 0.5)).any()


def test_build_cost_adds_the_weighted_structure_term():
    rng = np.random.default_rng(0)
    cam = example_camera("pinhole", 320, 240)
    pts = np.column_stack(
        [rng.uniform(-2, 2, 4000), rng.uniform(-1.5, 1.5, 4000), rng.uniform(4, 8, 4000)]
    )
    pair = RegistrationPair(cam, rng.random((240, 320)), pts, rng.random(4000))
    config = RefineConfig(hidden_point_removal=False, parallel=False, orientation_classes=False)
    T = np.eye(4)
    off, _ = build_cost([pair], T, config)
    on, _ = build_cost([pair], T, replace(config, structure_weight=0.5))
    assert len(off.costs) == 1 and len(on.costs) == 2
    scores, edges = pair.structure()
    extra = NIDCost(cam, edges, pts, scores, parallel=False).value(T)
    assert_allclose(on.value(T), off.value(T) + 0.5 * extra, rtol=1e-12)
    assert pair.structure()[0] is scores  # made once
    with pytest.raises(ValueError):
        RefineConfig(structure_weight=-1.0)
