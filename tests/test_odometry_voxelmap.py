"""Voxel grids of the odometry: the local voxel map, downsampling and de-duplication.

Kernels (nbcalib.kernels.voxelmap) == the brute-force references (nbcalib.reference.integrate).
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose
from tolerances import TOL

from nbcalib.odometry import voxelmap as V
from nbcalib.reference import integrate as ref

# ---------------------------------------------------------------------------------------------
# Voxel map: kernel == brute-force reference
# ---------------------------------------------------------------------------------------------


def _nasty_cloud(rng, n=3000):
    """Points on a few planes plus clutter, with exact duplicates and points on voxel faces."""
    plane = np.column_stack([rng.uniform(-3, 3, n), rng.uniform(-3, 3, n), np.zeros(n)])
    clutter = rng.uniform(-3, 3, (n // 3, 3))
    faces = np.round(rng.uniform(-3, 3, (200, 3)) * 2.0) / 2.0  # exactly on 0.5 m voxel faces
    dupes = plane[:100].copy()
    return np.vstack([plane, clutter, faces, dupes])


@pytest.mark.parametrize("min_spacing", [0.0, 0.05])
def test_voxelmap_insert_matches_reference(rng, min_spacing):
    points = _nasty_cloud(rng)
    kernel_map = V.VoxelMap(0.5, max_points_per_voxel=7, min_spacing=min_spacing, capacity=16)
    reference_map = ref.VoxelMapReference(0.5, 7, min_spacing)
    for chunk in np.array_split(points, 3):  # several insertions, with growth of the table
        assert kernel_map.insert(chunk) == reference_map.insert(chunk)
    kernel_points, kernel_flat = kernel_map.points()
    reference_points, reference_flat = reference_map.points()
    assert np.array_equal(kernel_flat, reference_flat)
    assert np.array_equal(kernel_points, reference_points)


@pytest.mark.parametrize(("k", "max_distance"), [(1, 0.5), (5, 0.5), (8, 0.2)])
def test_voxelmap_knn_is_exact(rng, k, max_distance):
    """27-voxel search with max_distance <= voxel == brute force over all stored points."""
    points = _nasty_cloud(rng)
    vmap = V.VoxelMap(0.5, max_points_per_voxel=9, min_spacing=0.0)
    vmap.insert(points)
    stored, flat = vmap.points()
    queries = np.vstack([rng.uniform(-3.5, 3.5, (300, 3)), stored[:50], points[-100:-90]])
    idx, d2 = vmap.knn(queries, k, max_distance)
    idx_ref, d2_ref = ref.knn_bruteforce(stored, flat, queries, k, max_distance)
    assert np.array_equal(idx, idx_ref)
    assert np.array_equal(d2, d2_ref)


def test_voxelmap_remove_far_keeps_near_voxels(rng):
    vmap = V.VoxelMap(1.0, max_points_per_voxel=4)
    points = rng.uniform(-20, 20, (4000, 3))
    vmap.insert(points)
    before, _ = vmap.points()
    vmap.remove_far(np.zeros(3), 10.0)
    after, _ = vmap.points()
    assert 0 < len(after) < len(before)
    assert np.linalg.norm(after, axis=1).max() < 10.0 + np.sqrt(3)  # voxel centre within 10 m
    # what stayed is still found: a query at a kept point finds it at distance 0
    idx, d2 = vmap.knn(after[:20], 1, 1.0)
    assert np.all(d2[:, 0] == 0.0)
    assert np.array_equal(vmap.point(idx[:, 0]), after[:20])


def test_voxel_extent_is_checked():
    vmap = V.VoxelMap(0.002)
    with pytest.raises(ValueError, match="voxel grid covers"):
        vmap.insert(np.array([[3000.0, 0.0, 0.0]]))


# ---------------------------------------------------------------------------------------------
# Downsampling and de-duplication: kernel == reference
# ---------------------------------------------------------------------------------------------


def test_voxel_downsample_matches_reference(rng):
    points = _nasty_cloud(rng)
    assert np.array_equal(V.voxel_downsample(points, 0.3), ref.voxel_first_indices(points, 0.3))


def test_stratified_downsample(rng):
    points = _nasty_cloud(rng)
    idx = V.stratified_downsample(points, 0.5, 1000)
    assert np.all(np.diff(idx) > 0)
    n_voxels = len(ref.voxel_first_indices(points, 0.5))
    assert 1000 <= len(idx) < 1000 + n_voxels
    assert np.array_equal(idx, V.stratified_downsample(points, 0.5, 1000))  # deterministic
    assert np.array_equal(V.stratified_downsample(points, 0.5, 10**6), np.arange(len(points)))
    few = V.stratified_downsample(points, 0.01, 500)  # more voxels than target: thinned
    assert len(few) == 500


@pytest.mark.parametrize("rule", ["mean", "last"])
def test_voxel_deduplicate_matches_reference(rng, rule):
    points = np.vstack([_nasty_cloud(rng), _nasty_cloud(rng)[:500] + 1e-4])
    intensity = rng.uniform(0, 255, len(points))
    got = V.voxel_deduplicate(points, intensity, voxel_size=0.05, rule=rule)
    want = ref.voxel_deduplicate(points, intensity, 0.05, rule)
    if rule == "last":  # copies of input values: exact
        assert np.array_equal(got[0], want[0])
        assert np.array_equal(got[1], want[1])
    else:  # sums in the same order, one division each
        assert_allclose(got[0], want[0], **TOL["kernel_vs_reference"])
        assert_allclose(got[1], want[1], **TOL["kernel_vs_reference"])
    # one point per voxel, in order of first appearance
    keys = np.floor(got[0] / 0.05)
    assert len(np.unique(keys, axis=0)) == len(keys)
