"""Ray casting against a scene of analytic primitives (the synthetic sensor rig's renderer).

A scene is a flat ``(P, PRIM_SIZE)`` float64 array, one row per primitive, laid out as

====================  =========================================================================
columns               meaning
====================  =========================================================================
``PRIM_TYPE``         :data:`RECTANGLE`, :data:`BOX`, :data:`CYLINDER` or :data:`ELLIPSOID`
``PRIM_MATERIAL``     material index (into the scene's material table; unused here)
``PRIM_CENTER:+3``    centre ``c`` in the world frame, metres
``PRIM_AXES:+9``      ``R_local_world`` row-major: row ``k`` is local axis ``k`` in the world
``PRIM_HALF:+3``      half-extents along the local axes, metres (see below)
====================  =========================================================================

A world point ``p`` has local coordinates ``R_local_world @ (p - c)``; ray parameters ``t`` (metres
along a unit direction) are the same in both frames. Half-extents per type:

- rectangle: ``(a, b, -)``; the patch ``|x| <= a, |y| <= b`` of the local plane ``z = 0``,
  two-sided.
- box: ``(a, b, c)``; hit from outside, or from inside when the origin is inside (a room).
- cylinder: ``(r, -, h)``; axis = local z, radius ``r``, ``|z| <= h``, capped.
- ellipsoid: ``(a, b, c)``; semi-axes (a sphere when equal).

Each hit reports the ray parameter ``t``, the primitive, a face id, the world normal turned to face
the incoming ray (``n . d <= 0``, so shading is two-sided) and surface coordinates ``(s, u)`` in
metres, the input of the procedural textures:

- rectangle: face 0, ``(x + a, y + b)``.
- box: face ``2 k + (0 if negative side else 1)`` for the face normal to local axis ``k``;
  side faces (``k`` = 0, 1) use ``(horizontal, z + c)``, top and bottom ``(x + a, y + b)``.
- cylinder: face 0 side ``(r (atan2(y, x) + pi), z + h)``, 1 bottom / 2 top cap ``(x + r, y + r)``.
- ellipsoid: face 0, ``(m atan2(y/b, x/a), m asin(z/c))`` with the mean semi-axis ``m``.

Semantics shared with the slow reference :func:`nbcalib.reference.raycast.cast_rays`: a hit needs
``t_min < t < t_max``; the nearest hit wins, and on an exact tie the lower primitive index wins.
The kernels walk a bounding volume hierarchy (built by :func:`nbcalib.synthetic.bvh.build_bvh`);
the reference tests every primitive, so comparing the two also tests the hierarchy.
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_parallel

RECTANGLE = 0
BOX = 1
CYLINDER = 2
ELLIPSOID = 3

PRIM_TYPE = 0
PRIM_MATERIAL = 1
PRIM_CENTER = 2
PRIM_AXES = 5
PRIM_HALF = 14
PRIM_SIZE = 17

#: depth of the traversal stack; a median-split tree of 2**40 primitives would need 41
_STACK_SIZE = 64
#: directions below this are treated as parallel to a plane or slab
_PARALLEL_EPS = 1e-15


@jit
def _to_local(prims, i, x, y, z):
    """Rotate a world vector into primitive ``i``'s local axes (no translation)."""
    a = PRIM_AXES
    lx = prims[i, a + 0] * x + prims[i, a + 1] * y + prims[i, a + 2] * z
    ly = prims[i, a + 3] * x + prims[i, a + 4] * y + prims[i, a + 5] * z
    lz = prims[i, a + 6] * x + prims[i, a + 7] * y + prims[i, a + 8] * z
    return lx, ly, lz


@jit
def _to_world(prims, i, lx, ly, lz):
    """Rotate a local vector of primitive ``i`` back into the world frame."""
    a = PRIM_AXES
    x = prims[i, a + 0] * lx + prims[i, a + 3] * ly + prims[i, a + 6] * lz
    y = prims[i, a + 1] * lx + prims[i, a + 4] * ly + prims[i, a + 7] * lz
    z = prims[i, a + 2] * lx + prims[i, a + 5] * ly + prims[i, a + 8] * lz
    return x, y, z


@jit
def _intersect_rectangle(ox, oy, oz, dx, dy, dz, ha, hb, t_min, t_max):
    if abs(dz) < _PARALLEL_EPS:
        return np.inf, -1
    t = -oz / dz
    if t <= t_min or t >= t_max:
        return np.inf, -1
    if abs(ox + t * dx) > ha or abs(oy + t * dy) > hb:
        return np.inf, -1
    return t, 0


@jit
def _intersect_box(ox, oy, oz, dx, dy, dz, ha, hb, hc, t_min, t_max):
    t_near = -np.inf
    t_far = np.inf
    near_face = -1
    far_face = -1
    for k in range(3):
        if k == 0:
            o, d, h = ox, dx, ha
        elif k == 1:
            o, d, h = oy, dy, hb
        else:
            o, d, h = oz, dz, hc
        if abs(d) < _PARALLEL_EPS:
            if abs(o) > h:
                return np.inf, -1
            continue
        t_lo = (-h - o) / d
        t_hi = (h - o) / d
        # entering through the negative face when moving in +d, the positive face otherwise
        lo_face = 2 * k if d > 0.0 else 2 * k + 1
        hi_face = 2 * k + 1 if d > 0.0 else 2 * k
        if t_lo > t_hi:
            t_lo, t_hi = t_hi, t_lo
        if t_lo > t_near:
            t_near = t_lo
            near_face = lo_face
        if t_hi < t_far:
            t_far = t_hi
            far_face = hi_face
    if t_near > t_far:
        return np.inf, -1
    if t_min < t_near < t_max:
        return t_near, near_face
    if t_min < t_far < t_max:
        return t_far, far_face
    return np.inf, -1


@jit
def _intersect_cylinder(ox, oy, oz, dx, dy, dz, r, hc, t_min, t_max):
    best = np.inf
    face = -1
    a = dx * dx + dy * dy
    if a > 1e-30:
        b = ox * dx + oy * dy
        c = ox * ox + oy * oy - r * r
        disc = b * b - a * c
        if disc >= 0.0:
            sq = math.sqrt(disc)
            for root in range(2):
                t = (-b - sq) / a if root == 0 else (-b + sq) / a
                if t_min < t < t_max and abs(oz + t * dz) <= hc:
                    best = t
                    face = 0
                    break
    if abs(dz) >= _PARALLEL_EPS:
        for cap in range(2):
            zc = -hc if cap == 0 else hc
            t = (zc - oz) / dz
            if t_min < t < t_max and t < best:
                x = ox + t * dx
                y = oy + t * dy
                if x * x + y * y <= r * r:
                    best = t
                    face = 1 + cap
    return best, face


@jit
def _intersect_ellipsoid(ox, oy, oz, dx, dy, dz, ha, hb, hc, t_min, t_max):
    ux, uy, uz = ox / ha, oy / hb, oz / hc
    vx, vy, vz = dx / ha, dy / hb, dz / hc
    a = vx * vx + vy * vy + vz * vz
    b = ux * vx + uy * vy + uz * vz
    c = ux * ux + uy * uy + uz * uz - 1.0
    disc = b * b - a * c
    if disc < 0.0:
        return np.inf, -1
    sq = math.sqrt(disc)
    t = (-b - sq) / a
    if t_min < t < t_max:
        return t, 0
    t = (-b + sq) / a
    if t_min < t < t_max:
        return t, 0
    return np.inf, -1


@jit
def _intersect(prims, i, px, py, pz, dx, dy, dz, t_min, t_max):
    """Ray parameter and face of the first hit of primitive ``i`` in ``(t_min, t_max)``.

    Returns ``(inf, -1)`` on a miss. ``p`` is the ray origin, ``d`` its unit direction (world).
    """
    c = PRIM_CENTER
    ox, oy, oz = _to_local(prims, i, px - prims[i, c], py - prims[i, c + 1], pz - prims[i, c + 2])
    lx, ly, lz = _to_local(prims, i, dx, dy, dz)
    h = PRIM_HALF
    kind = int(prims[i, PRIM_TYPE])
    if kind == RECTANGLE:
        return _intersect_rectangle(
            ox, oy, oz, lx, ly, lz, prims[i, h], prims[i, h + 1], t_min, t_max
        )
    if kind == BOX:
        return _intersect_box(
            ox, oy, oz, lx, ly, lz, prims[i, h], prims[i, h + 1], prims[i, h + 2], t_min, t_max
        )
    if kind == CYLINDER:
        return _intersect_cylinder(
            ox, oy, oz, lx, ly, lz, prims[i, h], prims[i, h + 2], t_min, t_max
        )
    return _intersect_ellipsoid(
        ox, oy, oz, lx, ly, lz, prims[i, h], prims[i, h + 1], prims[i, h + 2], t_min, t_max
    )


@jit
def _hit_attributes(prims, i, face, px, py, pz, dx, dy, dz, t):
    """World normal (facing the ray) and surface coordinates of an :func:`_intersect` hit."""
    c = PRIM_CENTER
    h = PRIM_HALF
    wx = px + t * dx - prims[i, c]
    wy = py + t * dy - prims[i, c + 1]
    wz = pz + t * dz - prims[i, c + 2]
    x, y, z = _to_local(prims, i, wx, wy, wz)
    ha, hb, hc = prims[i, h], prims[i, h + 1], prims[i, h + 2]
    kind = int(prims[i, PRIM_TYPE])
    nx, ny, nz = 0.0, 0.0, 1.0
    s, u = 0.0, 0.0
    if kind == RECTANGLE:
        s, u = x + ha, y + hb
    elif kind == BOX:
        axis = face // 2
        sign = 1.0 if face % 2 == 1 else -1.0
        if axis == 0:
            nx, ny, nz = sign, 0.0, 0.0
            s, u = y + hb, z + hc
        elif axis == 1:
            nx, ny, nz = 0.0, sign, 0.0
            s, u = x + ha, z + hc
        else:
            nx, ny, nz = 0.0, 0.0, sign
            s, u = x + ha, y + hb
    elif kind == CYLINDER:
        if face == 0:
            rho = math.sqrt(x * x + y * y)
            nx, ny, nz = x / rho, y / rho, 0.0
            s, u = ha * (math.atan2(y, x) + math.pi), z + hc
        else:
            nz = -1.0 if face == 1 else 1.0
            s, u = x + ha, y + ha
    else:
        gx, gy, gz = x / (ha * ha), y / (hb * hb), z / (hc * hc)
        norm = math.sqrt(gx * gx + gy * gy + gz * gz)
        nx, ny, nz = gx / norm, gy / norm, gz / norm
        mean = (ha + hb + hc) / 3.0
        sz = min(1.0, max(-1.0, z / hc))
        s, u = mean * math.atan2(y / hb, x / ha), mean * math.asin(sz)
    nwx, nwy, nwz = _to_world(prims, i, nx, ny, nz)
    if nwx * dx + nwy * dy + nwz * dz > 0.0:
        nwx, nwy, nwz = -nwx, -nwy, -nwz
    return nwx, nwy, nwz, s, u


@jit
def _slab_entry(bounds, node, px, py, pz, ix, iy, iz, t_min, t_max):
    """Entry parameter of the ray into the node's box, ``inf`` when it misses ``(t_min, t_max)``."""
    t0x = (bounds[node, 0] - px) * ix
    t1x = (bounds[node, 3] - px) * ix
    t0y = (bounds[node, 1] - py) * iy
    t1y = (bounds[node, 4] - py) * iy
    t0z = (bounds[node, 2] - pz) * iz
    t1z = (bounds[node, 5] - pz) * iz
    t_near = max(max(min(t0x, t1x), min(t0y, t1y)), max(min(t0z, t1z), t_min))
    t_far = min(min(max(t0x, t1x), max(t0y, t1y)), min(max(t0z, t1z), t_max))
    if t_near > t_far:
        return np.inf
    return t_near


@jit
def _inverse(d):
    """Reciprocal of a direction component, finite for zero (slab tests without 0 * inf)."""
    if abs(d) < 1e-300:
        return 1e300 if d >= 0.0 else -1e300
    return 1.0 / d


@jit
def _new_stack():
    """Scratch space of one traversal: pairs (node, entry distance), as float64."""
    return np.empty(2 * _STACK_SIZE, dtype=np.float64)


@jit
def _closest_hit(prims, bounds, nodes, order, stack, px, py, pz, dx, dy, dz, t_min, t_max):
    """Nearest hit of one ray through the hierarchy: ``(t, primitive, face)``, ``(inf, -1, -1)``.

    ``stack`` is scratch space from :func:`_new_stack` (allocated once per batch of rays). Nodes
    are visited nearest entry first; a node whose box the ray enters beyond the best hit so far
    is skipped (an entry *equal* to it is not, for the tie rule).
    """
    ix, iy, iz = _inverse(dx), _inverse(dy), _inverse(dz)
    best_t = np.inf
    best_i = -1
    best_face = -1
    if nodes.shape[0] == 0:
        return best_t, best_i, best_face
    t_root = _slab_entry(bounds, 0, px, py, pz, ix, iy, iz, t_min, t_max)
    if t_root == np.inf:
        return best_t, best_i, best_face
    stack[0] = 0.0
    stack[1] = t_root
    top = 1
    while top > 0:
        top -= 1
        if stack[2 * top + 1] > best_t:
            continue
        node = int(stack[2 * top])
        count = nodes[node, 2]
        if count > 0:
            start = nodes[node, 1]
            for k in range(start, start + count):
                i = order[k]
                t, face = _intersect(prims, i, px, py, pz, dx, dy, dz, t_min, t_max)
                if t < best_t or (t == best_t and t < np.inf and i < best_i):
                    best_t = t
                    best_i = i
                    best_face = face
            continue
        left = nodes[node, 0]
        limit = min(t_max, best_t)
        t_left = _slab_entry(bounds, left, px, py, pz, ix, iy, iz, t_min, limit)
        t_right = _slab_entry(bounds, left + 1, px, py, pz, ix, iy, iz, t_min, limit)
        # push the farther child first, so the nearer one is visited next
        if t_left <= t_right:
            first, t_first, second, t_second = left + 1, t_right, left, t_left
        else:
            first, t_first, second, t_second = left, t_left, left + 1, t_right
        if t_first < np.inf:
            stack[2 * top] = first
            stack[2 * top + 1] = t_first
            top += 1
        if t_second < np.inf:
            stack[2 * top] = second
            stack[2 * top + 1] = t_second
            top += 1
    return best_t, best_i, best_face


@jit
def _any_hit(prims, bounds, nodes, order, stack, px, py, pz, dx, dy, dz, t_min, t_max):
    """Tell whether the ray hits anything in ``(t_min, t_max)`` (shadow rays; first hit ends)."""
    if nodes.shape[0] == 0:
        return False
    ix, iy, iz = _inverse(dx), _inverse(dy), _inverse(dz)
    stack[0] = 0.0
    top = 1
    while top > 0:
        top -= 1
        node = int(stack[top])
        if _slab_entry(bounds, node, px, py, pz, ix, iy, iz, t_min, t_max) == np.inf:
            continue
        count = nodes[node, 2]
        if count > 0:
            start = nodes[node, 1]
            for k in range(start, start + count):
                t, _ = _intersect(prims, order[k], px, py, pz, dx, dy, dz, t_min, t_max)
                if t < np.inf:
                    return True
            continue
        stack[top] = nodes[node, 0]
        stack[top + 1] = nodes[node, 0] + 1
        top += 2
    return False


#: rays per batch of the kernels below: one traversal stack per batch, batches run in parallel
_BATCH = 1024


def _cast_rays_body(
    prims,
    bounds,
    nodes,
    order,
    origins,
    directions,
    t_min,
    t_max,
    out_t,
    out_prim,
    out_face,
    out_normal,
    out_surface,
):
    n = origins.shape[0]
    for batch in prange((n + _BATCH - 1) // _BATCH):
        stack = np.empty(_STACK_SIZE, dtype=np.int64)
        for r in range(batch * _BATCH, min(n, (batch + 1) * _BATCH)):
            px, py, pz = origins[r, 0], origins[r, 1], origins[r, 2]
            dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
            out_t[r] = np.inf
            out_prim[r] = -1
            out_face[r] = -1
            for k in range(3):
                out_normal[r, k] = np.nan
            out_surface[r, 0] = np.nan
            out_surface[r, 1] = np.nan
            if not (np.isfinite(px + py + pz) and np.isfinite(dx + dy + dz)):
                continue
            t, i, face = _closest_hit(
                prims, bounds, nodes, order, stack, px, py, pz, dx, dy, dz, t_min, t_max
            )
            if i < 0:
                continue
            out_t[r] = t
            out_prim[r] = i
            out_face[r] = face
            nx, ny, nz, s, u = _hit_attributes(prims, i, face, px, py, pz, dx, dy, dz, t)
            out_normal[r, 0] = nx
            out_normal[r, 1] = ny
            out_normal[r, 2] = nz
            out_surface[r, 0] = s
            out_surface[r, 1] = u


def _occluded_body(prims, bounds, nodes, order, origins, directions, t_min, t_max, out):
    n = origins.shape[0]
    for batch in prange((n + _BATCH - 1) // _BATCH):
        stack = np.empty(_STACK_SIZE, dtype=np.int64)
        for r in range(batch * _BATCH, min(n, (batch + 1) * _BATCH)):
            px, py, pz = origins[r, 0], origins[r, 1], origins[r, 2]
            dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
            out[r] = False
            if not (np.isfinite(px + py + pz) and np.isfinite(dx + dy + dz)) or t_max[r] <= t_min:
                continue
            out[r] = _any_hit(
                prims, bounds, nodes, order, stack, px, py, pz, dx, dy, dz, t_min, t_max[r]
            )


#: nearest hit per ray (serial); fills out_t, out_prim, out_face, out_normal, out_surface
_cast_rays = jit(_cast_rays_body)
#: the same with ``prange`` over rays; each ray writes only its own row, so it equals the serial one
_cast_rays_parallel = jit_parallel(_cast_rays_body)
#: any hit per ray within its own ``t_max[r]`` (serial)
_occluded = jit(_occluded_body)
#: the same with ``prange`` over rays
_occluded_parallel = jit_parallel(_occluded_body)
