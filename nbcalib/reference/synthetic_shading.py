"""Slow, readable reference of the shading kernel in :mod:`nbcalib.kernels.synthetic_shading`.

One camera ray at a time: the nearest hit from the brute-force reference ray caster
(:func:`nbcalib.reference.raycast.cast_rays`, no hierarchy), the albedo from the reference
texture (:func:`nbcalib.reference.synthetic_texture.material_at`), then the light that reaches the
hit, with a shadow ray per light source. The semantics are those of the kernel module's
docstring. The ray caster's reference intersects boxes as six rectangles, so distances, normals
and hence the radiance agree with the kernel to ``TOL["raycast_vs_reference"]``, not bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.reference.raycast import cast_rays
from nbcalib.reference.synthetic_texture import lerp, material_at

__all__ = ["radiance"]


def _nearest_hit(prims, origin, direction, t_max=np.inf):
    """``(t, primitive, face, normal, surface)`` of one ray; primitive -1 on a miss."""
    t, prim, face, normal, surface = cast_rays(prims, origin[None], direction[None], t_max=t_max)
    return t[0], int(prim[0]), int(face[0]), normal[0], surface[0]


def _blocked(prims, origin, direction, t_max):
    """Whether anything lies along the ray within ``(0, t_max)``."""
    return _nearest_hit(prims, origin, direction, t_max)[1] >= 0


def _irradiance(prims, point, normal, sun, ambient, lights, shadows):
    """Light reaching a surface point with unit ``normal``: ambient, the sun, point lights."""
    irradiance = ambient * (0.7 + 0.3 * normal[2])
    sun_direction, sun_irradiance = sun[:3], sun[3]
    facing = float(normal @ sun_direction)
    if sun_irradiance > 0.0 and facing > 0.0:
        if not (shadows and _blocked(prims, point, sun_direction, np.inf)):
            irradiance += sun_irradiance * facing
    for x, y, z, power in lights:
        to_light = np.array([x, y, z]) - point
        distance = math.sqrt(float(to_light @ to_light))
        to_light = to_light / distance
        facing = float(normal @ to_light)
        if facing <= 0.0:
            continue
        if shadows and _blocked(prims, point, to_light, distance - 1e-3):
            continue
        irradiance += power * facing / max(distance, 0.3) ** 2
    return irradiance


def radiance(
    prims,
    materials,
    gap,
    origin,
    directions,
    pixel_angle,
    lighting,
    shadows,
    *,
    off=0,
    shading=True,
):
    """Linear RGB radiance along camera rays, the slow way (reference of ``_shade``).

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The scene's primitives, world frame.
    materials : ndarray of shape (M, MAT_SIZE), float64
        The material table.
    gap : float
        Modality gap in [0, 1].
    origin : ndarray of shape (3,), float64
        Camera centre, world frame, metres.
    directions : ndarray of shape (N, 3), float64
        Unit ray directions, world frame.
    pixel_angle : ndarray of shape (N,), float64
        Angular size of each ray's pixel, radians.
    lighting : tuple
        ``(sun, ambient, lights, sky_top, sky_horizon)``, the kernel's lighting arguments:
        ``sun`` (4,) the unit direction towards the sun then its irradiance, ``ambient`` a float,
        ``lights`` (L, 4) the point lights ``(x, y, z, power)`` (world frame, metres),
        ``sky_top`` and ``sky_horizon`` (3,) the sky radiance at the zenith and the horizon.
    shadows : bool
        Cast shadow rays.
    off : int
        Bit mask of texture differences switched off (``OFF_*`` of
        :mod:`nbcalib.kernels.synthetic_texture`).
    shading : bool
        False: the irradiance is ``ambient + sun irradiance`` at every hit (no normal, no point
        lights, no shadows).

    Returns
    -------
    radiance : ndarray of shape (N, 3), float64
    t : ndarray of shape (N,), float64
        Distance to the surface seen, metres; ``inf`` for the sky, NaN for invalid rays.
    prim : ndarray of shape (N,), int64
        Primitive seen, -1 for none.
    """
    sun, ambient, lights, sky_top, sky_horizon = lighting
    origin = np.asarray(origin, dtype=np.float64)
    n = len(directions)
    out = np.zeros((n, 3))
    out_t = np.full(n, np.nan)
    out_prim = np.full(n, -1, dtype=np.int64)
    for r in range(n):
        d = np.asarray(directions[r], dtype=np.float64)
        if not np.all(np.isfinite(d)):
            continue
        t, i, face, normal, (s, u) = _nearest_hit(prims, origin, d)
        if i < 0:
            out_t[r] = np.inf
            height = math.sqrt(min(1.0, max(0.0, d[2])))
            out[r] = [lerp(sky_horizon[c], sky_top[c], height) for c in range(3)]
            continue
        out_t[r], out_prim[r] = t, i
        cos_incidence = abs(float(normal @ d))
        footprint = t * pixel_angle[r] / max(cos_incidence, 0.15)
        albedo, _, _, _ = material_at(prims, materials, i, face, s, u, footprint, gap, off)
        if shading:
            # shadow rays start a little off the surface, on the side the camera sees
            point = origin + t * d + 1e-4 * normal
            light = _irradiance(prims, point, normal, sun, ambient, lights, shadows)
        else:
            light = ambient + sun[3]  # the same light everywhere
        out[r] = np.asarray(albedo) * light
    return out, out_t, out_prim
