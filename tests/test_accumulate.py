"""Static accumulation: scans of a LiDAR at rest de-duplicated into one dense cloud."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.errors import InputError
from nbcalib.preprocess.accumulate import integrate_static
from nbcalib.reference import integrate as ref


def test_integrate_static_dedups_and_filters_range(rng):
    scan = np.column_stack([rng.uniform(-5, 5, (1000, 3)), rng.uniform(0, 1, 1000)])
    scan[:10, :3] *= 0.01  # within min_distance
    scans = [scan, scan + np.array([1e-4, 0, 0, 0]), scan[:300]]
    cloud = integrate_static(scans, voxel_size=0.01, min_distance=1.0, dedup="last")
    points = np.vstack([s[:, :3] for s in scans])
    intensity = np.concatenate([s[:, 3] for s in scans])
    near = np.linalg.norm(points, axis=1) < 1.0
    want = ref.voxel_deduplicate(points[~near], intensity[~near], 0.01, "last")
    assert np.array_equal(cloud.points, want[0]) and np.array_equal(cloud.intensity, want[1])
    assert cloud.T_first_scanbegin.shape == (3, 4, 4)
    assert np.array_equal(cloud.T_first_scanend[1], np.eye(4))
    assert cloud.stats["points_used"].tolist() == [int((~near[:1000]).sum())] * 2 + [
        int((~near[:300]).sum())
    ]


def test_integrate_static_accepts_pointcloud_objects(rng):
    from nbcalib.io.pointcloud import PointCloud

    pts = rng.uniform(2, 5, (100, 3))
    cloud = integrate_static([PointCloud(points=pts, intensity=np.arange(100.0))])
    assert len(cloud) == 100
    assert_allclose(cloud.intensity, np.arange(100.0))
    no_intensity = integrate_static([pts])
    assert np.all(no_intensity.intensity == 0.0)


def test_bad_input_raises_clear_errors(rng):
    scan = np.column_stack([rng.uniform(2, 5, (100, 3)), rng.uniform(0, 1, 100)])
    with pytest.raises(InputError, match="no scans"):
        integrate_static([])
    with pytest.raises(InputError, match="no finite point"):
        integrate_static([np.full((50, 4), np.nan), np.zeros((0, 3))])
    with pytest.raises(ValueError, match=r"shape \(N, 3\) or \(N, 4\)"):
        integrate_static([np.zeros((5, 2))])
    with pytest.raises(ValueError, match="dedup"):
        integrate_static([scan], dedup="median")
    with pytest.raises(ValueError, match="min_distance"):
        integrate_static([scan], min_distance=-1.0)
