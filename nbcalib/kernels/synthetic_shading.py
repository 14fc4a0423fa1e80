"""Shading kernel of the synthetic camera: one ray per pixel, textures, sun, point lights, shadows.

The public wrapper is :func:`nbcalib.synthetic.render.radiance` (and ``render_image`` above
it, which adds exposure, blur and noise). Per ray ``d`` from the camera centre ``o`` (world
frame), semantics shared with the slow reference :mod:`nbcalib.reference.synthetic_shading`:

- a ray with a non-finite direction is black, distance NaN, primitive -1;
- a ray that hits nothing (``0 < t < inf``) sees the sky, ``lerp(sky_horizon, sky_top,
  sqrt(clip(d_z, 0, 1)))`` per channel, distance ``inf``;
- otherwise, at the nearest hit (:mod:`nbcalib.kernels.raycast`) with the normal ``n`` facing the
  ray, the camera albedo (:func:`nbcalib.kernels.synthetic_texture._material_at`, footprint
  ``t * pixel_angle / max(|n . d|, 0.15)``) times the irradiance
  ``ambient (0.7 + 0.3 n_z) + sun_irradiance max(0, n . s) [lit]
  + sum_k power_k max(0, n . l_k) / max(r_k, 0.3)**2 [lit]``; shadow rays start at
  ``o + t d + 1e-4 n`` and look for any hit in ``(0, inf)`` towards the sun and
  ``(0, r_k - 1e-3)`` towards light ``k`` at distance ``r_k`` (``shadows=False``: all lit);
- ``shading=False`` (``nbcalib synth --without shading``): the irradiance is the constant
  ``ambient + sun_irradiance`` at every hit (no normal, no sun angle, no point lights, hence no
  shadow rays either), so the radiance is the albedo times a constant; the sky is unchanged;
- ``off`` is passed to the texture (the ``OFF_*`` bits of
  :mod:`nbcalib.kernels.synthetic_texture`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_parallel
from nbcalib.kernels.raycast import _BATCH, _any_hit, _closest_hit, _hit_attributes, _new_stack
from nbcalib.kernels.synthetic_texture import _material_at


def _shade_body(
    prims,
    bounds,
    nodes,
    order,
    materials,
    gap,
    off,
    origin,
    directions,
    pixel_angle,
    sun,
    ambient,
    lights,
    sky_top,
    sky_horizon,
    shadows,
    shading,
    out_radiance,
    out_t,
    out_prim,
):
    """Linear radiance of each pixel's ray: cast, texture, ambient + sun + point lights, shadows.

    ``sun`` = (unit direction towards the sun, irradiance); ``lights`` (L, 4) = (x, y, z, power).
    ``out_t`` gets the hit distance (``inf`` for the sky, NaN for an invalid ray). ``shading``
    False: every hit gets the irradiance ``ambient + sun[3]``; ``off``: texture bits.
    """
    n = directions.shape[0]
    ox, oy, oz = origin[0], origin[1], origin[2]
    for batch in prange((n + _BATCH - 1) // _BATCH):
        stack = _new_stack()
        for r in range(batch * _BATCH, min(n, (batch + 1) * _BATCH)):
            dx, dy, dz = directions[r, 0], directions[r, 1], directions[r, 2]
            out_radiance[r, 0] = 0.0
            out_radiance[r, 1] = 0.0
            out_radiance[r, 2] = 0.0
            out_t[r] = np.nan
            out_prim[r] = -1
            if not np.isfinite(dx + dy + dz):
                continue
            t, i, face = _closest_hit(
                prims, bounds, nodes, order, stack, ox, oy, oz, dx, dy, dz, 0.0, np.inf
            )
            if i < 0:
                out_t[r] = np.inf
                w = math.sqrt(min(1.0, max(0.0, dz)))
                for c in range(3):
                    out_radiance[r, c] = sky_horizon[c] + (sky_top[c] - sky_horizon[c]) * w
                continue
            out_t[r] = t
            out_prim[r] = i
            nx, ny, nz, s, u = _hit_attributes(prims, i, face, ox, oy, oz, dx, dy, dz, t)
            cos_incidence = abs(nx * dx + ny * dy + nz * dz)
            fw = t * pixel_angle[r] / max(cos_incidence, 0.15)
            red, green, blue, _, _, _ = _material_at(
                prims, materials, i, face, s, u, fw, gap, off, True, False
            )
            if not shading:
                flat = ambient + sun[3]
                out_radiance[r, 0] = red * flat
                out_radiance[r, 1] = green * flat
                out_radiance[r, 2] = blue * flat
                continue
            # shadow rays start a little off the surface, on the side the camera sees
            px = ox + t * dx + 1e-4 * nx
            py = oy + t * dy + 1e-4 * ny
            pz = oz + t * dz + 1e-4 * nz
            irradiance = ambient * (0.7 + 0.3 * nz)
            facing = nx * sun[0] + ny * sun[1] + nz * sun[2]
            if sun[3] > 0.0 and facing > 0.0:
                if not shadows or not _any_hit(
                    prims,
                    bounds,
                    nodes,
                    order,
                    stack,
                    px,
                    py,
                    pz,
                    sun[0],
                    sun[1],
                    sun[2],
                    0.0,
                    np.inf,
                ):
                    irradiance += sun[3] * facing
            for k in range(lights.shape[0]):
                lx, ly, lz = lights[k, 0] - px, lights[k, 1] - py, lights[k, 2] - pz
                distance = math.sqrt(lx * lx + ly * ly + lz * lz)
                lx, ly, lz = lx / distance, ly / distance, lz / distance
                facing = nx * lx + ny * ly + nz * lz
                if facing <= 0.0:
                    continue
                if shadows and _any_hit(
                    prims, bounds, nodes, order, stack, px, py, pz, lx, ly, lz, 0.0, distance - 1e-3
                ):
                    continue
                irradiance += lights[k, 3] * facing / max(distance, 0.3) ** 2
            out_radiance[r, 0] = red * irradiance
            out_radiance[r, 1] = green * irradiance
            out_radiance[r, 2] = blue * irradiance


#: radiance, hit distance and primitive per camera ray (serial)
_shade = jit(_shade_body)
#: the same with ``prange`` over batches of rays; each ray writes only its own row, so it equals
#: the serial one
_shade_parallel = jit_parallel(_shade_body)
