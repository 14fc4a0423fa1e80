"""The synthetic rig's texture, shading and LiDAR kernels against their slow references.

Small, nasty inputs: every pattern, negative and lattice-aligned surface coordinates, zero and
huge footprints, misses and invalid rays, rays from inside a box, retro-reflectors, glass,
returns pushed out of range by the noise; each texture switch of ``nbcalib synth --without``
(the ``off`` bits) on its own and all together, and the shading switched off. Parallel variants
must equal the serial ones exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from tolerances import TOL

from nbcalib.kernels import raycast as rc
from nbcalib.kernels import synthetic_lidar as sl
from nbcalib.kernels import synthetic_shading as sh
from nbcalib.kernels import synthetic_texture as tx
from nbcalib.reference.synthetic_lidar import returns as returns_reference
from nbcalib.reference.synthetic_shading import radiance as radiance_reference
from nbcalib.reference.synthetic_texture import surface_properties as surface_reference
from nbcalib.synthetic.builder import SceneBuilder
from nbcalib.synthetic.texture import PATTERNS, Material
from nbcalib.transforms import random_rotation

GAPS = (0.0, 0.37, 1.0)
#: every texture switch (the kernels' ``off`` bits)
ALL_OFF = tx.OFF_CAMERA_TEXTURE | tx.OFF_LIDAR_TEXTURE | tx.OFF_MATERIALS | tx.OFF_ELEMENTS
#: each switch on its own, and all of them
OFFS = (tx.OFF_CAMERA_TEXTURE, tx.OFF_LIDAR_TEXTURE, tx.OFF_MATERIALS, tx.OFF_ELEMENTS, ALL_OFF)


def _materials(rng):
    """Every pattern at three scales, random colours and noise, some retro, some with dropout."""
    rows = []
    for k, name in enumerate(PATTERNS):
        for scale in (0.04, 2.7, 8.0):
            rows.append(
                Material(
                    name,
                    scale,
                    tuple(rng.uniform(0, 1, 3)),
                    tuple(rng.uniform(0, 1, 3)),
                    rng.uniform(0.0, 3.0),
                    rng.uniform(0.0, 1.2),
                    camera_noise=rng.uniform(0, 0.4),
                    lidar_noise=rng.uniform(0, 0.4),
                    noise_scale=rng.choice([0.03, 0.5, 4.0]),
                    seed=int(rng.integers(0, 10**6)),
                    dropout=rng.choice([0.0, 0.6]),
                    retro=bool(k % 3 == 0),
                ).row()
            )
    return np.stack(rows)


def _texture_inputs(rng, n=4000):
    materials = _materials(rng)
    prims = np.zeros((2 * len(materials) + 3, rc.PRIM_SIZE))
    prims[:, rc.PRIM_MATERIAL] = np.arange(len(prims)) % len(materials)
    prim = rng.integers(-1, len(prims), n)
    face = rng.integers(0, 6, n)
    scale = materials[prims[prim, rc.PRIM_MATERIAL].astype(int), tx.MAT_SCALE][:, None]
    # each coordinate on its own: anywhere, within a pattern period or so of the corner (signs,
    # road markings across), on the lattice (multiples of the scale), or far from the origin
    modes = [
        rng.uniform(-40.0, 120.0, (n, 2)),
        rng.uniform(-0.5, 1.5, (n, 2)) * scale,
        rng.integers(-30, 30, (n, 2)) * scale,
        rng.uniform(-5e3, 5e3, (n, 2)),
    ]
    mode = rng.choice(4, size=(n, 2), p=[0.4, 0.4, 0.15, 0.05])
    surface = np.choose(mode, modes)
    surface[:10] = 0.0
    # footprints from none to far larger than any detail, absolute and relative to the scale
    footprint = rng.choice([0.0, 1e-9, 0.01, 0.3, 1e3], n) * rng.uniform(0.5, 1.5, n)
    relative = rng.random(n) < 0.5
    footprint[relative] = (rng.choice([0.0, 0.03, 0.045, 0.2, 1.0], n) * scale[:, 0])[relative]
    return prims, materials, prim, face, surface, footprint


def _surface_kernel(
    prims, materials, prim, face, surface, footprint, gap, *, off=0, parallel=False
):
    n = len(prim)
    out = (np.empty((n, 3)), np.empty(n), np.empty(n), np.empty(n, dtype=np.bool_))
    kernel = tx._surface_properties_parallel if parallel else tx._surface_properties
    kernel(prims, materials, prim, face, surface, footprint, gap, off, *out)
    return out


@pytest.mark.parametrize("gap", GAPS)
def test_texture_kernel_matches_reference(gap):
    rng = np.random.default_rng(7)
    args = _texture_inputs(rng)
    got = _surface_kernel(*args, gap)
    want = surface_reference(*args, gap)
    hit = args[2] >= 0
    assert 0.8 < hit.mean() < 1.0
    for g, w in zip(got[:3], want[:3]):  # albedo, reflectivity, dropout
        assert_array_equal(np.isnan(g), np.isnan(w))
        assert_allclose(g[hit], w[hit], **TOL["kernel_vs_reference"])
    assert_array_equal(got[3], want[3])
    if gap > 0:
        assert want[3].any() and (want[2] > 0).any()  # retro-reflectors and dropouts occur
        assert np.nanmax(want[1]) > 1.0
    else:
        assert not want[3].any()


@pytest.mark.parametrize("gap", [0.37, 1.0])
@pytest.mark.parametrize("off", OFFS)
def test_texture_kernel_matches_reference_with_switches(off, gap):
    rng = np.random.default_rng(7)
    args = _texture_inputs(rng, n=2000)
    got = _surface_kernel(*args, gap, off=off)
    want = surface_reference(*args, gap, off)
    hit = args[2] >= 0
    for g, w in zip(got[:3], want[:3]):
        assert_array_equal(np.isnan(g), np.isnan(w))
        assert_allclose(g[hit], w[hit], **TOL["kernel_vs_reference"])
    assert_array_equal(got[3], want[3])
    # each switch changes what it should: the camera texture the albedo (and the LiDAR through
    # the 1 - gap term only), the others the LiDAR alone
    default = _surface_kernel(*args, gap)
    camera_changed = not np.array_equal(got[0][hit], default[0][hit])
    lidar_changed = not np.array_equal(got[1][hit], default[1][hit])
    assert camera_changed == bool(off & tx.OFF_CAMERA_TEXTURE)
    assert lidar_changed == (off != tx.OFF_CAMERA_TEXTURE or gap < 1.0)
    if off & tx.OFF_MATERIALS:
        assert not got[3].any() and not got[2].any()  # no retro-reflectors, no glass dropouts
        assert np.nanmax(got[1]) <= 1.0
    else:
        assert_array_equal(got[2], default[2])


@pytest.mark.parametrize("off", OFFS)
def test_texture_switches_of_the_lidar_do_nothing_at_gap_zero(off):
    """At gap 0 the LiDAR sees the camera's albedo: only the camera texture switch acts."""
    rng = np.random.default_rng(10)
    args = _texture_inputs(rng, n=2000)
    got = _surface_kernel(*args, 0.0, off=off)
    default = _surface_kernel(*args, 0.0)
    for a, b in zip(got[:2], default[:2]):  # albedo, reflectivity
        assert np.array_equal(a, b, equal_nan=True) == (not off & tx.OFF_CAMERA_TEXTURE)
    assert not got[2].any() and not got[3].any()  # no dropouts, no retro-reflectors at gap 0


@pytest.mark.parametrize("name", PATTERNS)
def test_texture_kernel_matches_reference_on_each_pattern(name):
    """Dense samples where one pattern's details are (a few periods; a road's whole period)."""
    rng = np.random.default_rng(9)
    width = 8.0 if name == "road" else 1.0
    material = Material(name, width, (0.9, 0.5, 0.2), (0.1, 0.3, 0.6), 0.7, 2.5, retro=True)
    materials = material.row()[None]
    prims = np.zeros((3, rc.PRIM_SIZE))
    n = 3000
    prim = rng.integers(0, 3, n)
    face = rng.integers(0, 6, n)
    if name == "road":  # markings repeat every 60 m along the road
        surface = np.column_stack([rng.uniform(0.0, 60.0, n), rng.uniform(-0.5, 8.5, n)])
    elif name == "sign":  # one sign face, from its corner
        surface = rng.uniform(-0.1, 1.1, (n, 2))
    else:
        surface = rng.uniform(-1.5, 3.5, (n, 2))
    footprint = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.0, 0.3, n) * width)
    args = (prims, materials, prim, face, surface, footprint)
    got = _surface_kernel(*args, 0.8)
    want = surface_reference(*args, 0.8)
    for g, w in zip(got[:3], want[:3]):
        assert_allclose(g, w, **TOL["kernel_vs_reference"])
    assert_array_equal(got[3], want[3])


def test_texture_parallel_equals_serial():
    rng = np.random.default_rng(8)
    args = _texture_inputs(rng, n=6000)
    for gap, off in [(g, 0) for g in GAPS] + [(0.6, ALL_OFF)]:
        serial = _surface_kernel(*args, gap, off=off)
        parallel = _surface_kernel(*args, gap, off=off, parallel=True)
        for a, b in zip(serial, parallel):
            assert_array_equal(a, b)


def _scene(rng, *, enclosed):
    """Every primitive kind and several patterns; ``enclosed``: all of it inside a box."""
    b = SceneBuilder()
    mats = [
        b.material(Material(name, rng.uniform(0.05, 1.0), seed=k))
        for k, name in enumerate(PATTERNS)
    ]
    sign = b.material(
        Material("sign", 0.6, (0.8, 0.05, 0.03), (0.9, 0.9, 0.88), 4.0, 0.9, retro=True)
    )
    glass = b.material(Material("windows", 0.7, (0.6,) * 3, (0.1,) * 3, 0.5, 0.03, dropout=0.7))
    b.rectangle((0, 0, -1.5), (1, 0, 0), (0, 1, 0), (12, 12), mats[4], name="road")
    b.box((4, 1, 0), (1.0, 2.0, 1.5), mats[2], yaw=0.3)
    b.box((-3, -2, -0.5), (0.5, 0.5, 1.0), glass, yaw=1.1)
    b.cylinder((2, -4, 0), 0.6, 1.5, mats[9], axis=(0.2, 0.1, 1.0))
    b.ellipsoid((-4, 3, 1), (1.2, 0.7, 1.6), mats[7], yaw=0.7)
    b.sphere((0, 5, 0.5), 0.8, mats[11])
    b.rectangle((6, -3, 1), (0, 1, 0), (0, 0, 1), (0.5, 0.5), sign)
    b.rectangle((-6, 0, 2), (0.3, 1, 0.2), (0, 0.1, 1), (1.0, 0.6), mats[5])
    b.box((0, 0, 3.5), (1.5, 1.5, 0.1), mats[3])  # a roof over the origin: shadows
    if enclosed:
        b.box((0, 0, 1.0), (9.0, 9.0, 4.0), mats[1], name="room")
    scene = b.build()
    return scene.prims, scene.materials, scene.bvh_bounds, scene.bvh_nodes, scene.bvh_order


def _directions(rng, n):
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:6] = np.vstack([np.eye(3), -np.eye(3)])  # zero components
    return d


def _lighting(rng):
    sun = np.zeros(4)
    sun[:3] = rng.normal(size=3)
    sun[:3] /= np.linalg.norm(sun[:3])
    sun[2] = abs(sun[2])
    sun[3] = 1.0
    lights = np.array([[1.0, 1.0, 2.5, 4.0], [-5.0, -5.0, 1.0, 2.0], [0.0, 0.0, 0.1, 0.5]])
    return sun, 0.35, lights, np.array([0.35, 0.5, 0.85]), np.array([0.8, 0.85, 0.9])


def _shade_kernel(
    scene, gap, origin, directions, pixel_angle, light, shadows, *, off=0, shading=True, **kw
):
    prims, materials, bounds, nodes, order = scene
    n = len(directions)
    out = (np.empty((n, 3)), np.empty(n), np.empty(n, dtype=np.int64))
    kernel = sh._shade_parallel if kw.get("parallel") else sh._shade
    scene_args = (prims, bounds, nodes, order, materials, gap, off)
    kernel(*scene_args, origin, directions, pixel_angle, *light, shadows, shading, *out)
    return out


@pytest.mark.parametrize("enclosed", [False, True])
@pytest.mark.parametrize(
    "shadows, off, shading", [(True, 0, True), (False, 0, True), (True, ALL_OFF, False)]
)
def test_shading_kernel_matches_reference(enclosed, shadows, off, shading):
    rng = np.random.default_rng(11)
    scene = _scene(rng, enclosed=enclosed)
    origin = np.array([0.2, -0.1, 0.4])
    directions = _directions(rng, 300)
    directions[6] = np.nan  # an invalid pixel (outside the lens)
    pixel_angle = rng.choice([0.0, 1e-3, 0.05], 300)
    light = _lighting(rng)
    gap = 0.5
    switches = dict(off=off, shading=shading)
    got = _shade_kernel(scene, gap, origin, directions, pixel_angle, light, shadows, **switches)
    want = radiance_reference(
        scene[0], scene[1], gap, origin, directions, pixel_angle, light, shadows, **switches
    )
    assert_array_equal(got[2], want[2])
    assert_array_equal(np.isnan(got[1]), np.isnan(want[1]))
    hit = want[2] >= 0
    assert np.isnan(want[1][6])
    assert hit.mean() > 0.99 if enclosed else 0.3 < hit.mean() < 0.9  # the sky is seen or not
    assert_allclose(got[1][hit], want[1][hit], **TOL["synthetic_vs_reference"])
    assert_allclose(got[0], want[0], **TOL["synthetic_vs_reference"])


def test_shading_parallel_equals_serial():
    rng = np.random.default_rng(12)
    light = _lighting(rng)
    for enclosed in (False, True):
        scene = _scene(rng, enclosed=enclosed)
        directions = _directions(rng, 5000)
        pixel_angle = rng.uniform(0, 0.01, 5000)
        args = (scene, 1.0, np.array([0.2, -0.1, 0.4]), directions, pixel_angle, light, True)
        for switches in (dict(), dict(off=ALL_OFF, shading=False)):
            serial = _shade_kernel(*args, **switches)
            for a, b in zip(serial, _shade_kernel(*args, **switches, parallel=True)):
                assert_array_equal(a, b)


def test_shading_off_is_the_albedo_times_a_constant():
    """Without shading every hit gets ``ambient + sun irradiance``: no normal, lamps, shadows."""
    rng = np.random.default_rng(15)
    scene = _scene(rng, enclosed=True)
    directions = _directions(rng, 2000)
    origin = np.array([0.2, -0.1, 0.4])
    light = _lighting(rng)
    sharp = np.zeros(len(directions))  # pixels of no size: the texture unfiltered
    flat, _, prim = _shade_kernel(scene, 0.5, origin, directions, sharp, light, True, shading=False)
    _, hit_prim, hit_face, hit_surface = _cast(scene, origin, directions)
    assert_array_equal(prim, hit_prim)
    albedo = _surface_kernel(scene[0], scene[1], hit_prim, hit_face, hit_surface, sharp, 0.5)[0]
    sun, ambient = light[0], light[1]
    hit = prim >= 0
    assert hit.mean() > 0.99
    assert_array_equal(flat[hit], albedo[hit] * (ambient + sun[3]))
    shaded, _, _ = _shade_kernel(scene, 0.5, origin, directions, sharp, light, True)
    ratio = shaded[hit].sum(axis=1) / flat[hit].sum(axis=1)
    assert np.nanstd(ratio) > 0.1  # the shaded image varies with normals, lamps and shadows


def _cast(scene, origin, directions):
    """Nearest hits ``(t, prim, face, surface)`` of rays from one origin (the raycast kernel)."""
    prims, _, bounds, nodes, order = scene
    n = len(directions)
    out = (np.empty(n), np.empty(n, dtype=np.int64), np.empty(n, dtype=np.int64))
    out += (np.empty((n, 3)), np.empty((n, 2)))
    origins = np.ascontiguousarray(np.broadcast_to(origin, directions.shape))
    rc._cast_rays(prims, bounds, nodes, order, origins, directions, 0.0, np.inf, *out)
    return out[0], out[1], out[2], out[4]


def _scan(rng, n):
    """Poses, beams with their noise, parameters and start pose of one scan (the reference's
    arguments); the noise is big enough to push returns across the range limits."""
    k = 5
    rotations = np.stack([random_rotation(rng) for _ in range(k)])
    positions = rng.uniform(-0.5, 0.5, (k, 3))
    which = np.sort(rng.integers(0, k, n))
    params = np.array([0.5, 9.0, 10.0, 0.05, 1.3, 0.5, 5.0, 0.03, 0.003])
    directions = _directions(rng, n)
    # one beam in ten aimed at the retro-reflective sign of _scene
    aimed = np.arange(10, n, 10)
    target = np.array([6.0, -3.0, 1.0]) + rng.uniform(-0.4, 0.4, (len(aimed), 3)) * [0, 1, 1]
    world = target - positions[which[aimed]]
    directions[aimed] = np.einsum("nji,nj->ni", rotations[which[aimed]], world)
    directions[aimed] /= np.linalg.norm(directions[aimed], axis=1, keepdims=True)
    beams = (
        which,
        directions,
        rng.normal(scale=0.4, size=n),  # range noise, metres
        rng.normal(scale=0.3, size=n),  # intensity noise
        rng.random(n),  # dropout draws
    )
    start_pose = (random_rotation(rng), rng.uniform(-0.5, 0.5, 3))
    return (rotations, positions), beams, params, start_pose


def _returns_kernel(scene, gap, scan, *, off=0, parallel=False):
    prims, materials, bounds, nodes, order = scene
    poses, beams, params, start_pose = scan
    n = len(beams[0])
    out = (np.zeros(n, dtype=np.bool_), np.empty(n), np.empty(n), np.full((n, 3), np.nan))
    out += (np.empty(n, dtype=np.int64),)
    kernel = sl._returns_parallel if parallel else sl._returns
    scene_args = (prims, bounds, nodes, order, materials, gap, off)
    kernel(*scene_args, *poses, *beams, params, *start_pose, *out)
    return out


@pytest.mark.parametrize(
    "gap, off", [(g, 0) for g in GAPS] + [(1.0, tx.OFF_MATERIALS), (0.37, ALL_OFF)]
)
@pytest.mark.parametrize("enclosed", [False, True])
def test_lidar_kernel_matches_reference(gap, off, enclosed):
    rng = np.random.default_rng(13)
    scene = _scene(rng, enclosed=enclosed)
    scan = _scan(rng, 400)
    got = _returns_kernel(scene, gap, scan, off=off)
    want = returns_reference(scene[0], scene[1], gap, *scan, off=off)
    assert_array_equal(got[4], want[4])  # primitive hit, also for lost returns
    assert_array_equal(got[0], want[0])
    keep = want[0]
    assert 0.1 < keep.mean() < 0.95 and (want[4][~keep] >= 0).any()
    for k in (1, 2, 3):  # range, intensity, point at the scan start
        assert_allclose(got[k][keep], want[k][keep], **TOL["synthetic_vs_reference"])
    assert_array_equal(np.isnan(got[1]), ~keep)
    if gap > 0 and not off & tx.OFF_MATERIALS:
        assert (want[2][keep] == 255.0).any()  # a retro-reflector saturates


def test_lidar_parallel_equals_serial():
    rng = np.random.default_rng(14)
    for enclosed in (False, True):
        scene = _scene(rng, enclosed=enclosed)
        scan = _scan(rng, 5000)
        for off in (0, ALL_OFF):
            serial = _returns_kernel(scene, 1.0, scan, off=off)
            parallel = _returns_kernel(scene, 1.0, scan, off=off, parallel=True)
            for a, b in zip(serial, parallel):
                assert_array_equal(a, b)
