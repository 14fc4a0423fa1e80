"""Slow, readable reference of the ray caster in :mod:`nbcalib.kernels.raycast`.

Every ray is tested against every primitive (no hierarchy), one primitive at a time, in plain
NumPy. A box is six rectangles, a cylinder a tube and two discs, an ellipsoid a squashed unit
sphere. The semantics are those of the kernel module's docstring: a hit needs
``t_min < t < t_max``, the nearest hit wins, an exact tie goes to the lower primitive index, the
normal faces the incoming ray, and the surface coordinates are in metres.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels.raycast import (
    BOX,
    CYLINDER,
    PRIM_AXES,
    PRIM_CENTER,
    PRIM_HALF,
    PRIM_TYPE,
    RECTANGLE,
)

__all__ = ["cast_rays"]


def _plane_hit(origin, direction, axis, offset, t_min, t_max):
    """Parameter where a local-frame ray meets the plane ``x[axis] = offset``, or None."""
    if abs(direction[axis]) < 1e-15:
        return None
    t = (offset - origin[axis]) / direction[axis]
    return t if t_min < t < t_max else None


def _hits_rectangle(o, d, half, t_min, t_max):
    t = _plane_hit(o, d, 2, 0.0, t_min, t_max)
    if t is None:
        return []
    p = o + t * d
    if abs(p[0]) <= half[0] and abs(p[1]) <= half[1]:
        return [(t, 0)]
    return []


def _hits_box(o, d, half, t_min, t_max):
    hits = []
    for axis in range(3):
        for side in (0, 1):
            offset = half[axis] if side == 1 else -half[axis]
            t = _plane_hit(o, d, axis, offset, t_min, t_max)
            if t is None:
                continue
            p = o + t * d
            others = [k for k in range(3) if k != axis]
            if all(abs(p[k]) <= half[k] for k in others):
                hits.append((t, 2 * axis + side))
    return hits


def _hits_cylinder(o, d, half, t_min, t_max):
    radius, half_height = half[0], half[2]
    hits = []
    # the tube x^2 + y^2 = r^2
    a = d[0] ** 2 + d[1] ** 2
    if a > 1e-30:
        b = o[0] * d[0] + o[1] * d[1]
        c = o[0] ** 2 + o[1] ** 2 - radius**2
        disc = b * b - a * c
        if disc >= 0.0:
            for t in ((-b - math.sqrt(disc)) / a, (-b + math.sqrt(disc)) / a):
                if t_min < t < t_max and abs(o[2] + t * d[2]) <= half_height:
                    hits.append((t, 0))
    # the two discs
    for face, z in ((1, -half_height), (2, half_height)):
        t = _plane_hit(o, d, 2, z, t_min, t_max)
        if t is not None:
            p = o + t * d
            if p[0] ** 2 + p[1] ** 2 <= radius**2:
                hits.append((t, face))
    return hits


def _hits_ellipsoid(o, d, half, t_min, t_max):
    # scale space so the ellipsoid becomes the unit sphere; t is unchanged
    u = o / half
    v = d / half
    a = v @ v
    b = u @ v
    c = u @ u - 1.0
    disc = b * b - a * c
    if disc < 0.0:
        return []
    roots = ((-b - math.sqrt(disc)) / a, (-b + math.sqrt(disc)) / a)
    return [(t, 0) for t in roots if t_min < t < t_max]


def _attributes(kind, face, p, half):
    """Local normal and surface coordinates ``(s, u)`` of a local hit point ``p``."""
    x, y, z = p
    a, b, c = half
    if kind == RECTANGLE:
        return np.array([0.0, 0.0, 1.0]), (x + a, y + b)
    if kind == BOX:
        axis, sign = face // 2, (1.0 if face % 2 == 1 else -1.0)
        normal = np.zeros(3)
        normal[axis] = sign
        surface = {0: (y + b, z + c), 1: (x + a, z + c), 2: (x + a, y + b)}[axis]
        return normal, surface
    if kind == CYLINDER:
        if face == 0:
            rho = math.hypot(x, y)
            return np.array([x / rho, y / rho, 0.0]), (a * (math.atan2(y, x) + math.pi), z + c)
        return np.array([0.0, 0.0, -1.0 if face == 1 else 1.0]), (x + a, y + a)
    gradient = np.array([x / a**2, y / b**2, z / c**2])
    mean = (a + b + c) / 3.0
    latitude = math.asin(min(1.0, max(-1.0, z / c)))
    return gradient / np.linalg.norm(gradient), (mean * math.atan2(y / b, x / a), mean * latitude)


_HITS = {RECTANGLE: _hits_rectangle, BOX: _hits_box, CYLINDER: _hits_cylinder}


def cast_rays(prims, origins, directions, *, t_min=0.0, t_max=np.inf):
    """Cast rays against every primitive, one at a time (reference of ``_cast_rays``).

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The scene, laid out as in :mod:`nbcalib.kernels.raycast`.
    origins, directions : ndarray of shape (N, 3), float64
        Ray origins (world frame, metres) and unit directions.
    t_min, t_max : float
        Open interval of accepted ray parameters, metres.

    Returns
    -------
    t : ndarray of shape (N,), float64
        Distance to the nearest hit, ``inf`` on a miss.
    prim, face : ndarray of shape (N,), int64
        Primitive index and face id of the hit, -1 on a miss.
    normal : ndarray of shape (N, 3), float64
        World normal facing the ray, NaN on a miss.
    surface : ndarray of shape (N, 2), float64
        Surface coordinates in metres, NaN on a miss.
    """
    prims = np.asarray(prims, dtype=np.float64)
    n = len(origins)
    t_out = np.full(n, np.inf)
    prim_out = np.full(n, -1, dtype=np.int64)
    face_out = np.full(n, -1, dtype=np.int64)
    normal_out = np.full((n, 3), np.nan)
    surface_out = np.full((n, 2), np.nan)
    for r in range(n):
        origin = np.asarray(origins[r], dtype=np.float64)
        direction = np.asarray(directions[r], dtype=np.float64)
        if not (np.all(np.isfinite(origin)) and np.all(np.isfinite(direction))):
            continue
        best = (np.inf, -1, -1)
        for i, row in enumerate(prims):
            R_local_world = row[PRIM_AXES : PRIM_AXES + 9].reshape(3, 3)
            o = R_local_world @ (origin - row[PRIM_CENTER : PRIM_CENTER + 3])
            d = R_local_world @ direction
            kind = int(row[PRIM_TYPE])
            hits = _HITS.get(kind, _hits_ellipsoid)(
                o, d, row[PRIM_HALF : PRIM_HALF + 3], t_min, t_max
            )
            for t, face in sorted(hits):
                if t < best[0]:  # strictly nearer: on a tie the earlier (lower) index stays
                    best = (t, i, face)
                break
        t, i, face = best
        if i < 0:
            continue
        row = prims[i]
        R_local_world = row[PRIM_AXES : PRIM_AXES + 9].reshape(3, 3)
        p_local = R_local_world @ (origin + t * direction - row[PRIM_CENTER : PRIM_CENTER + 3])
        normal_local, surface = _attributes(
            int(row[PRIM_TYPE]), face, p_local, row[PRIM_HALF : PRIM_HALF + 3]
        )
        normal = R_local_world.T @ normal_local
        if normal @ direction > 0.0:
            normal = -normal
        t_out[r], prim_out[r], face_out[r] = t, i, face
        normal_out[r] = normal
        surface_out[r] = surface
    return t_out, prim_out, face_out, normal_out, surface_out
