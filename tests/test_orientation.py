"""Orientation classes and the orientation-conditioned NID (registration/orientation.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from numpy.testing import assert_allclose

from nbcalib.camera import example_camera
from nbcalib.registration.nid import MultiNIDCost, NIDCost
from nbcalib.registration.orientation import orientation_classes, point_normals
from nbcalib.registration.refine import RefineConfig, RegistrationPair, build_cost
from nbcalib.transforms import se3_exp


def room_corner(rng, n_per_plane=(6000, 6000, 6000)):
    """Points on a side wall (x = -3), a floor (y = 1.5) and a back wall (z = 8), camera frame
    of an identity extrinsic, with their true classes 0, 1, 2."""
    nx, ny, nz = n_per_plane
    side = np.column_stack([np.full(nx, -3.0), rng.uniform(-1.5, 1.4, nx), rng.uniform(3, 7.9, nx)])
    floor = np.column_stack([rng.uniform(-2.9, 3, ny), np.full(ny, 1.5), rng.uniform(3, 7.9, ny)])
    back = np.column_stack([rng.uniform(-2.9, 3, nz), rng.uniform(-1.5, 1.4, nz), np.full(nz, 8.0)])
    points = np.concatenate([side, floor, back])
    points += 0.002 * rng.standard_normal(points.shape)  # range noise
    truth = np.repeat([0, 1, 2], n_per_plane)
    return points, truth


def test_normals_and_classes_of_planes(rng):
    points, truth = room_corner(rng)
    normals = point_normals(points)
    assert_allclose(np.linalg.norm(normals, axis=1), 1.0, rtol=1e-9)
    axis_part = np.abs(normals[np.arange(len(truth)), truth])
    assert np.median(axis_part) > 0.999
    classes = orientation_classes(points)
    assert classes.dtype == np.int8
    # only points within a neighbourhood of a corner may be misclassified
    assert np.mean(classes == truth) > 0.99


def test_covariance_kernel_matches_reference(rng):
    from nbcalib.kernels.normals import neighbourhood_covariances
    from nbcalib.reference.normals import neighbourhood_covariances as reference

    points = rng.normal(size=(500, 3)) * [3.0, 1.0, 0.01] + [10.0, -4.0, 2.0]
    for k in (1, 3, 16):
        neighbours = rng.integers(0, len(points), (200, k)).astype(np.int32)
        assert_allclose(
            neighbourhood_covariances(points, neighbours),
            reference(points, neighbours),
            rtol=1e-12,
            atol=1e-12,
        )
    with pytest.raises(ValueError, match="index"):
        neighbourhood_covariances(points, np.array([[0, 500]]))
    with pytest.raises(ValueError, match="integer"):
        neighbourhood_covariances(points, np.zeros((3, 2)))


def test_normals_equal_the_plain_numpy_ones(rng):
    """The kernel and the fast KD-tree give the normals of the gather-einsum-eigh original."""
    from scipy.spatial import cKDTree

    points, _ = room_corner(rng)
    _, idx = cKDTree(points).query(points, k=16)
    centred = points[idx] - points[idx].mean(axis=1, keepdims=True)
    plain = np.linalg.eigh(np.einsum("nki,nkj->nij", centred, centred))[1][:, :, 0]
    normals = point_normals(points)
    assert np.abs(np.sum(plain * normals, axis=1)).min() > 1 - 1e-9


def test_normals_bad_input():
    with pytest.raises(ValueError, match="shape"):
        point_normals(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="at least 3"):
        point_normals(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        point_normals(np.array([[0.0, 0, 1], [1, 0, 1], [np.nan, 1, 1], [0, 1, 1]]))


def test_weighted_multi_cost(rng):
    cam = example_camera("pinhole", 320, 240)
    image = rng.random((240, 320))
    costs = []
    for _ in range(3):
        uv = rng.uniform([2, 2], [317, 237], (3000, 2))
        costs.append(NIDCost(cam, image, cam.unproject(uv) * 5.0, rng.random(3000)))
    weights = [0.5, 0.3, 0.2]
    multi = MultiNIDCost(costs, weights)
    T = se3_exp(np.array([0.01, 0, 0, 0, 0.01, 0]))
    value, grad = multi.value_and_grad(T)
    assert_allclose(value, sum(w * c.value(T) for w, c in zip(weights, costs)), rtol=1e-12)
    assert_allclose(
        grad, sum(w * c.value_and_grad(T)[1] for w, c in zip(weights, costs)), rtol=1e-12
    )
    for bad in ([1.0, 2.0], [1.0, -1.0, 1.0], [1.0, np.nan, 1.0]):
        with pytest.raises(ValueError, match="weights"):
            MultiNIDCost(costs, bad)


def _pair(rng, n_per_plane):
    cam = example_camera("pinhole", 640, 480)
    points, truth = room_corner(rng, n_per_plane)
    _, in_view = cam.project(points, in_image=True)
    points, truth = points[in_view], truth[in_view]
    image = rng.random((480, 640))
    pair = RegistrationPair(cam, image, points, rng.random(len(points)))
    return pair, truth


def test_build_cost_is_the_point_weighted_mean_of_class_nids(rng):
    pair, truth = _pair(rng, (7000, 8000, 9000))
    pair.classes = truth.astype(np.int8)  # given classes are used as they are
    config = RefineConfig(
        cost="nid", hidden_point_removal=False, parallel=False, min_class_points=1000
    )
    T = np.eye(4)
    cost, counts = build_cost([pair], T, config)
    assert len(cost.costs) == 3
    assert_allclose(cost.weights.sum(), 1.0, rtol=1e-12)
    assert sorted(len(c) for c in cost.costs) == sorted(np.bincount(truth).tolist())
    expected = 0.0
    for c in range(3):
        sel = truth == c
        part = NIDCost(pair.camera, pair.image, pair.points_lidar[sel], pair.intensities[sel])
        expected += sel.mean() * part.value(T)
    assert_allclose(cost.value(T), expected, rtol=1e-9)
    assert counts == [len(truth)]

    # switched off, or one class too small: the plain NID over all points
    plain = NIDCost(pair.camera, pair.image, pair.points_lidar, pair.intensities).value(T)
    off, _ = build_cost([pair], T, replace(config, orientation_classes=False))
    assert len(off.costs) == 1 and off.value(T) == pytest.approx(plain, rel=1e-12)
    small, _ = build_cost([pair], T, replace(config, min_class_points=np.bincount(truth).min() + 1))
    assert len(small.costs) == 1 and small.value(T) == pytest.approx(plain, rel=1e-12)


def test_classes_are_computed_once_and_only_where_asked(rng, monkeypatch):
    pair, truth = _pair(rng, (3000, 3000, 3000))
    points = pair.points_lidar.copy()
    points[5] = np.nan  # the cost drops it; it gets class 0 and no neighbours
    pair = RegistrationPair(pair.camera, pair.image, points, pair.intensities)
    some = np.arange(0, len(truth), 2)
    first = pair.orientation_classes(some)
    assert np.all(pair.classes[some] >= 0) and np.all(pair.classes[1::2] == -1)
    assert pair.classes[5] == -1  # not asked for yet (its class, 0, is checked below)
    ok = np.isfinite(pair.points_lidar[some]).all(axis=1)
    assert np.mean(first[ok] == truth[some][ok]) > 0.98

    import nbcalib.registration.orientation as orientation

    def fail(*args, **kwargs):
        raise AssertionError("normals computed twice")

    monkeypatch.setattr(orientation, "point_normals", fail)
    assert np.array_equal(pair.orientation_classes(some), first)
    monkeypatch.undo()
    everything = pair.orientation_classes()
    assert np.array_equal(everything[some], first) and np.all(everything >= 0)
    assert everything[5] == 0
    # the same classes as computing all at once
    fresh = RegistrationPair(pair.camera, pair.image, pair.points_lidar, pair.intensities)
    assert np.array_equal(fresh.orientation_classes(), everything)


def test_config_rejects_bad_min_class_points():
    with pytest.raises(ValueError, match="min_class_points"):
        RefineConfig(min_class_points=0)


def test_classes_belong_to_the_cloud(rng):
    """Pairs made from one another share their cloud's classes; another cloud has its own."""
    from dataclasses import replace as dc_replace

    pair, _ = _pair(rng, (3000, 3000, 3000))
    classes = pair.orientation_classes()
    moved = dc_replace(pair, camera=example_camera("pinhole", 320, 240))
    assert moved.cloud is pair.cloud and moved.classes is pair.classes
    points, values = pair.points_lidar[:150], pair.intensities[:150]
    fewer = RegistrationPair(pair.camera, pair.image, points, values)
    assert fewer.classes is None
    assert fewer.orientation_classes().shape == (150,) and np.all(fewer.classes >= 0)
    flipped = RegistrationPair(
        pair.camera, pair.image, pair.points_lidar[::-1].copy(), pair.intensities[::-1].copy()
    )
    assert np.array_equal(flipped.orientation_classes(), classes[::-1])


def fresh_classes(pair):
    return RegistrationPair(
        pair.camera, pair.image, pair.points_lidar, pair.intensities
    ).orientation_classes()
