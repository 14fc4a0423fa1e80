"""Lifting LiDAR-image keypoints through the index map, and pooling over pairs."""

from __future__ import annotations

import numpy as np
import pytest

from nbcalib.matching.correspondences import (
    Correspondences,
    correspondences_from_matches,
    lift_lidar_pixels,
    lift_matches,
    pool_correspondences,
)
from nbcalib.matching.matches import Matches


def _index_map():
    index = np.full((6, 8), -1, dtype=np.int32)
    index[2, 3] = 10
    index[2, 5] = 11
    index[4, 3] = 12
    index[0, 0] = 13
    return index


def test_own_pixel_is_the_rounded_position():
    index = _index_map()
    # floor(u + 0.5): 2.5 -> 3, 3.49 -> 3, 1.5 -> 2 (rows)
    rows = lift_lidar_pixels([[2.5, 1.5], [3.49, 2.2], [3.0, 2.0]], index, search_radius=0.0)
    assert rows.tolist() == [10, 10, 10]
    # 2.49 rounds to column 2, which is empty: not found without a search radius
    assert lift_lidar_pixels([[2.49, 2.0]], index, search_radius=0.0).tolist() == [-1]


def test_empty_pixel_takes_the_nearest_filled_pixel_within_the_radius():
    index = _index_map()
    # (4.2, 2.0): own pixel (4, 2) is empty; (5, 2) is 0.8 away, (3, 2) 1.2 away
    assert lift_lidar_pixels([[4.2, 2.0]], index, search_radius=2.0).tolist() == [11]
    # (3.0, 3.1): (3, 2) is 1.1 away, (3, 4) 0.9 away
    assert lift_lidar_pixels([[3.0, 3.1]], index, search_radius=2.0).tolist() == [12]
    # 1.5 px radius does not reach (3, 2) from (1.2, 2.0) (distance 1.8)
    assert lift_lidar_pixels([[1.2, 2.0]], index, search_radius=1.5).tolist() == [-1]
    assert lift_lidar_pixels([[1.2, 2.0]], index, search_radius=2.0).tolist() == [10]
    # exactly between two filled pixels: the first in (distance, row, column) order
    assert lift_lidar_pixels([[4.0, 2.0]], index, search_radius=1.0).tolist() == [10]
    # off the image, but a filled pixel is within reach
    assert lift_lidar_pixels([[-0.9, -0.4]], index, search_radius=1.0).tolist() == [13]
    assert lift_lidar_pixels([[-5.0, -5.0]], index, search_radius=2.0).tolist() == [-1]
    assert lift_lidar_pixels(np.empty((0, 2)), index).shape == (0,)


def test_bad_arguments():
    with pytest.raises(ValueError, match="finite"):
        lift_lidar_pixels([[np.nan, 0.0]], _index_map())
    with pytest.raises(ValueError, match="search_radius"):
        lift_lidar_pixels([[0.0, 0.0]], _index_map(), search_radius=-1.0)
    with pytest.raises(ValueError, match="index_map"):
        lift_lidar_pixels([[0.0, 0.0]], np.zeros((3, 3), dtype=float))


def test_lift_matches_drops_unlifted_and_pools_pairs():
    index = _index_map()
    cloud = np.arange(14 * 3, dtype=float).reshape(14, 3)
    uv_camera = np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 3.0]])
    uv_lidar = np.array([[3.0, 2.0], [7.0, 5.0], [5.1, 2.0]])
    a = lift_matches(uv_camera, uv_lidar, index, cloud, name="a")
    assert len(a) == 2 and a.n_matches == 3
    assert a.point_index.tolist() == [10, 11]
    assert np.array_equal(a.points_lidar, cloud[[10, 11]])
    assert np.array_equal(a.uv_camera, uv_camera[[0, 2]])
    assert a.confidence is None and np.array_equal(a.weights, [1.0, 1.0])
    matches = Matches(uv_camera, uv_lidar[::-1], np.array([2, -1, 0]), np.array([0.3, 0, 0.9]))
    b = correspondences_from_matches(matches, index, cloud, name="b")
    assert b.point_index.tolist() == [10, 11] and b.n_matches == 2
    assert b.confidence.tolist() == [0.3, 0.9]
    pooled = pool_correspondences([a, b, a])
    assert pooled.names == ("a", "b") and len(pooled) == 6 and pooled.n_matches == 8
    assert pooled.pair.tolist() == [0, 0, 1, 1, 0, 0]
    assert pooled.count_per_pair() == {"a": 4, "b": 2}
    assert pooled.confidence.tolist() == [1.0, 1.0, 0.3, 0.9, 1.0, 1.0]
    assert len(pool_correspondences([])) == 0
    assert len(Correspondences.empty(["x"])) == 0
    with pytest.raises(ValueError, match="refers to point"):
        lift_matches(uv_camera, uv_lidar, index, cloud[:5])
