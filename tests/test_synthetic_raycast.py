"""The numba ray caster against its slow reference, its hierarchy, and the texture kernel."""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from tolerances import TOL

from nbcalib.kernels import raycast as rc
from nbcalib.kernels.synthetic_texture import LUMA
from nbcalib.reference.raycast import cast_rays as cast_rays_reference
from nbcalib.synthetic.builder import SceneBuilder
from nbcalib.synthetic.bvh import build_bvh, primitive_bounds
from nbcalib.synthetic.scenes import make_scene
from nbcalib.synthetic.texture import Material, surface_properties
from nbcalib.transforms import random_rotation


def _random_scene(rng, n=40):
    """Every primitive kind, randomly placed, sized and turned (boxes and cylinders tilted)."""
    b = SceneBuilder()
    mat = b.material(Material())
    for k in range(n):
        center = rng.uniform(-6, 6, 3)
        kind = k % 5
        if kind == 0:
            R = random_rotation(rng)
            b.rectangle(center, R[0], R[1], rng.uniform(0.2, 2.0, 2), mat)
        elif kind == 1:
            b.box(center, rng.uniform(0.1, 1.5, 3), mat, yaw=rng.uniform(0, np.pi))
        elif kind == 2:
            axis = rng.normal(size=3)
            b.cylinder(center, rng.uniform(0.05, 1.0), rng.uniform(0.1, 2.0), mat, axis=axis)
        elif kind == 3:
            b.ellipsoid(center, rng.uniform(0.2, 1.5, 3), mat, yaw=rng.uniform(0, np.pi))
        else:
            b.sphere(center, rng.uniform(0.1, 1.0), mat)
    # a tilted box: replace its axes by a random rotation
    scene = b.build()
    prims = scene.prims.copy()
    for i in range(1, n, 5):
        prims[i, rc.PRIM_AXES : rc.PRIM_AXES + 9] = random_rotation(rng).ravel()
    bounds, nodes, order = build_bvh(prims)
    return prims, bounds, nodes, order


def _random_rays(rng, n, prims):
    """Rays from anywhere, half of them aimed near a primitive's centre."""
    origins = rng.uniform(-8, 8, (n, 3))
    directions = rng.normal(size=(n, 3))
    aimed = rng.random(n) < 0.5
    targets = prims[rng.integers(0, len(prims), n), rc.PRIM_CENTER : rc.PRIM_CENTER + 3]
    directions[aimed] = (
        targets[aimed] + rng.normal(scale=0.5, size=(aimed.sum(), 3)) - origins[aimed]
    )
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    # axis-aligned directions (zero components), a non-finite origin and direction
    directions[:6] = np.vstack([np.eye(3), -np.eye(3)])
    origins[6] = np.nan
    directions[7] = np.nan
    return origins, directions


def _cast(
    prims, bounds, nodes, order, origins, directions, *, parallel=False, t_min=0.0, t_max=np.inf
):
    n = len(origins)
    out = (
        np.empty(n),
        np.empty(n, dtype=np.int64),
        np.empty(n, dtype=np.int64),
        np.empty((n, 3)),
        np.empty((n, 2)),
    )
    kernel = rc._cast_rays_parallel if parallel else rc._cast_rays
    kernel(prims, bounds, nodes, order, origins, directions, t_min, t_max, *out)
    return out


@pytest.mark.parametrize("seed", range(4))
def test_kernel_matches_reference(seed):
    rng = np.random.default_rng(seed)
    prims, bounds, nodes, order = _random_scene(rng)
    origins, directions = _random_rays(rng, 400, prims)
    got = _cast(prims, bounds, nodes, order, origins, directions)
    want = cast_rays_reference(prims, origins, directions)
    assert 0.2 < np.mean(want[1] >= 0) < 0.98  # the rays do hit and miss
    assert_array_equal(got[1], want[1])
    assert_array_equal(got[2], want[2])
    hit = want[1] >= 0
    assert_array_equal(np.isinf(got[0]), ~hit)
    for k in (0, 3, 4):  # distance, normal, surface coordinates
        assert_allclose(got[k][hit], want[k][hit], **TOL["raycast_vs_reference"])
    assert np.all(np.isnan(got[3][~hit])) and np.all(np.isnan(got[4][~hit]))
    # normals are unit and face the incoming ray
    assert_allclose(np.linalg.norm(got[3][hit], axis=1), 1.0, atol=1e-12)
    assert np.all(np.einsum("ni,ni->n", got[3][hit], directions[hit]) <= 0.0)


def test_kernel_matches_reference_with_range_limits(rng):
    prims, bounds, nodes, order = _random_scene(rng)
    origins, directions = _random_rays(rng, 300, prims)
    got = _cast(prims, bounds, nodes, order, origins, directions, t_min=1.0, t_max=6.0)
    want = cast_rays_reference(prims, origins, directions, t_min=1.0, t_max=6.0)
    assert_array_equal(got[1], want[1])
    hit = want[1] >= 0
    assert np.all((got[0][hit] > 1.0) & (got[0][hit] < 6.0))
    assert_allclose(got[0][hit], want[0][hit], **TOL["raycast_vs_reference"])


def test_inside_box_hits_its_walls_from_inside():
    b = SceneBuilder()
    b.box((0, 0, 0), (2.0, 3.0, 1.5), Material())
    scene = b.build()
    directions = np.vstack([np.eye(3), -np.eye(3)])
    hits = scene.cast(np.zeros(3), directions)
    assert_allclose(hits.t, [2.0, 3.0, 1.5, 2.0, 3.0, 1.5])
    assert_array_equal(hits.face, [1, 3, 5, 0, 2, 4])
    assert_allclose(hits.normal, -directions)  # facing back at the ray


def test_ties_go_to_the_lower_index():
    b = SceneBuilder()
    mat = b.material(Material())
    for _ in range(5):  # five coincident rectangles
        b.rectangle((0, 0, 2.0), (1, 0, 0), (0, 1, 0), (1.0, 1.0), mat)
    scene = b.build()
    hits = scene.cast(np.zeros(3), [[0.0, 0.0, 1.0], [0.1, 0.0, 0.995]])
    assert_array_equal(hits.prim, [0, 0])
    want = cast_rays_reference(scene.prims, np.zeros((2, 3)), [[0.0, 0.0, 1.0], [0.1, 0.0, 0.995]])
    assert_array_equal(want[1], [0, 0])


def test_parallel_equals_serial_and_occlusion_agrees(rng):
    scene = make_scene(kind="street", seed=3)
    directions = rng.normal(size=(20_000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    serial = scene.cast(np.zeros(3), directions)
    parallel = scene.cast(np.zeros(3), directions, parallel=True)
    for a, b in zip(
        (serial.t, serial.prim, serial.face, serial.normal, serial.surface),
        (parallel.t, parallel.prim, parallel.face, parallel.normal, parallel.surface),
    ):
        assert_array_equal(a, b)
    limit = rng.uniform(1.0, 40.0, len(directions))
    origins = np.zeros_like(directions)
    for par in (False, True):
        blocked = scene.occluded(origins, directions, limit, parallel=par)
        assert_array_equal(blocked, serial.t < limit)


def test_bvh_holds_every_primitive_once_and_nests():
    scene = make_scene(kind="room", seed=5)
    assert_array_equal(np.sort(scene.bvh_order), np.arange(len(scene.prims)))
    lo, hi = primitive_bounds(scene.prims)
    for node, (first, start, count) in enumerate(scene.bvh_nodes):
        box = scene.bvh_bounds[node]
        if count > 0:
            members = scene.bvh_order[start : start + count]
            assert np.all(lo[members] >= box[:3]) and np.all(hi[members] <= box[3:])
        else:
            for child in (first, first + 1):
                assert np.all(scene.bvh_bounds[child, :3] >= box[:3])
                assert np.all(scene.bvh_bounds[child, 3:] <= box[3:])


def test_surface_properties_parallel_equals_serial_and_gap_zero_is_luminance(rng):
    scene = make_scene(kind="street", seed=1)
    directions = rng.normal(size=(5000, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = scene.cast(np.zeros(3), directions)
    footprint = scene.footprint(hits, directions, 0.002)
    args = (scene.prims, scene.materials, hits.prim, hits.face, hits.surface)
    serial = surface_properties(*args, footprint=footprint)
    parallel = surface_properties(*args, footprint=footprint, parallel=True)
    for a, b in zip(serial, parallel):
        assert_array_equal(a, b)
    albedo, reflectivity, _, retro = surface_properties(*args, footprint=footprint, gap=0.0)
    hit = hits.hit
    assert_allclose(reflectivity[hit], albedo[hit] @ np.asarray(LUMA), rtol=0, atol=1e-12)
    assert not retro.any()
    assert np.all(np.isnan(albedo[~hit]))


def test_materials_differ_between_modalities_as_designed():
    """Vegetation: dark for the camera, bright for the LiDAR; retro-reflectors saturate."""
    b = SceneBuilder()
    leaves = Material("leaves", 0.25, (0.04, 0.12, 0.03), (0.1, 0.28, 0.06), 0.65, 0.85)
    sign = Material("sign", 0.6, (0.8, 0.05, 0.03), (0.9, 0.9, 0.88), 4.0, 0.9, retro=True)
    b.rectangle((0, 0, 2), (1, 0, 0), (0, 1, 0), (1, 1), leaves)
    b.rectangle((0, 0, -2), (1, 0, 0), (0, 1, 0), (0.3, 0.3), sign)
    scene = b.build()
    rng = np.random.default_rng(0)
    xy = rng.uniform(-0.25, 0.25, (500, 2))
    up = np.column_stack([xy, np.full(500, 2.0)])
    down = np.column_stack([xy, np.full(500, -2.0)])
    directions = np.vstack([up, down])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = scene.cast(np.zeros(3), directions)
    albedo, reflectivity, _, retro = scene.surface_properties(hits)
    luminance = albedo @ np.asarray(LUMA)
    assert np.all(reflectivity[:500] > 3 * luminance[:500])
    assert retro[500:].mean() > 0.5 and not retro[:500].any()


def test_footprint_averages_fine_texture():
    """A checkerboard seen through a footprint much larger than its squares is uniform grey."""
    b = SceneBuilder()
    b.rectangle(
        (0, 0, 2),
        (1, 0, 0),
        (0, 1, 0),
        (1, 1),
        Material(
            "checker", 0.02, (1, 1, 1), (0, 0, 0), 0.9, 0.1, camera_noise=0.0, lidar_noise=0.0
        ),
    )
    scene = b.build()
    rng = np.random.default_rng(1)
    directions = np.column_stack([rng.uniform(-0.4, 0.4, (300, 2)), np.full(300, 2.0)])
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    hits = scene.cast(np.zeros(3), directions)
    sharp, _, _, _ = scene.surface_properties(hits, footprint=np.zeros(300))
    blurred, _, _, _ = scene.surface_properties(hits, footprint=np.full(300, 0.2))
    assert set(np.unique(sharp[:, 0])) == {0.0, 1.0}
    assert_allclose(blurred[:, 0], 0.5, atol=1e-12)
