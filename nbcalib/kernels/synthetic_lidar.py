"""LiDAR return kernel of the synthetic rig: cast each beam from its pose, then range and intensity.

The public wrapper is :func:`nbcalib.synthetic.lidar.simulate_scan`, which draws the noise and
looks up the poses. Per beam ``r``, semantics shared with the slow reference
:mod:`nbcalib.reference.synthetic_lidar`:

- the beam leaves ``positions[which[r]]`` along ``rotations[which[r]] @ directions_lidar[r]``
  (world frame) and takes the nearest hit in ``(0, reach)``; ``prim[r]`` is the primitive hit
  (-1 for none) even when the return is then lost;
- with the LiDAR reflectivity at the hit (:func:`nbcalib.kernels.synthetic_texture._material_at`,
  footprint ``t * beam_divergence / max(cos, 0.15)``, ``cos = |n . d|``), the range is
  ``t + range_noise[r]`` and the return is lost when the range is outside ``[min_range,
  max_range]``, ``cos <= 0.02``, ``lost[r] < dropout + material dropout``, or the signal
  ``reflectivity cos**incidence_exponent min(1, reference_range / range)**range_exponent`` is
  below ``min_signal`` (retro-reflectors are never too weak);
- a kept return has the intensity ``255 clip(v (1 + intensity_noise[r]), 0, 1)`` with ``v = 1``
  on a retro-reflector and ``min(signal, 1)`` elsewhere, and its point in the LiDAR frame at the
  scan start is ``start_rotation.T @ (origin + range d - start_position)``; rows of lost returns
  in ``out_start`` are left as they were;
- ``off`` is passed to the texture (the ``OFF_*`` bits of
  :mod:`nbcalib.kernels.synthetic_texture`). The LiDAR's own switches of ``nbcalib synth
  --without`` are plain parameters: ``lidar-noise`` zeroes the noise draws, ``dropout`` and
  ``beam_divergence``; ``lidar-falloff`` zeroes both exponents, so that the signal is the
  reflectivity itself.
"""

from __future__ import annotations

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_parallel
from nbcalib.kernels.raycast import _BATCH, _closest_hit, _hit_attributes, _new_stack
from nbcalib.kernels.synthetic_texture import _material_at


def _returns_body(
    prims,
    bounds,
    nodes,
    order,
    materials,
    gap,
    off,
    rotations,
    positions,
    which,
    directions_lidar,
    range_noise,
    intensity_noise,
    lost,
    params,
    start_rotation,
    start_position,
    out_keep,
    out_range,
    out_intensity,
    out_start,
    out_prim,
):
    """Every beam of a scan: cast from the pose of its firing time, then noise and intensity.

    ``params`` = (min_range, max_range, reach, dropout, incidence_exponent, range_exponent,
    reference_range, min_signal, beam_divergence). Beam ``r`` fires from pose ``which[r]``
    (``rotations`` R_world_lidar, ``positions`` t_world_lidar); ``out_start`` is its (noisy)
    point in the LiDAR frame at the scan start (pose ``start_rotation``, ``start_position``);
    ``off``: texture bits.
    """
    min_range, max_range, reach, dropout = params[0], params[1], params[2], params[3]
    incidence_exponent, range_exponent, reference_range = params[4], params[5], params[6]
    min_signal, divergence = params[7], params[8]
    n = directions_lidar.shape[0]
    for batch in prange((n + _BATCH - 1) // _BATCH):
        stack = _new_stack()
        for r in range(batch * _BATCH, min(n, (batch + 1) * _BATCH)):
            k = which[r]
            ox, oy, oz = positions[k, 0], positions[k, 1], positions[k, 2]
            ax, ay, az = directions_lidar[r, 0], directions_lidar[r, 1], directions_lidar[r, 2]
            dx = rotations[k, 0, 0] * ax + rotations[k, 0, 1] * ay + rotations[k, 0, 2] * az
            dy = rotations[k, 1, 0] * ax + rotations[k, 1, 1] * ay + rotations[k, 1, 2] * az
            dz = rotations[k, 2, 0] * ax + rotations[k, 2, 1] * ay + rotations[k, 2, 2] * az
            out_keep[r] = False
            out_range[r] = np.nan
            out_intensity[r] = np.nan
            out_prim[r] = -1
            t, i, face = _closest_hit(
                prims, bounds, nodes, order, stack, ox, oy, oz, dx, dy, dz, 0.0, reach
            )
            if i < 0:
                continue
            out_prim[r] = i
            nx, ny, nz, s, u = _hit_attributes(prims, i, face, ox, oy, oz, dx, dy, dz, t)
            cos_incidence = abs(nx * dx + ny * dy + nz * dz)
            fw = t * divergence / max(cos_incidence, 0.15)
            _, _, _, reflectivity, drop, retro = _material_at(
                prims, materials, i, face, s, u, fw, gap, off, False, True
            )
            distance = t + range_noise[r]
            if distance < min_range or distance > max_range or cos_incidence <= 0.02:
                continue
            range_term = min(1.0, reference_range / distance) ** range_exponent
            signal = reflectivity * cos_incidence**incidence_exponent * range_term
            if lost[r] < dropout + drop or (signal < min_signal and not retro):
                continue
            value = (1.0 if retro else min(signal, 1.0)) * (1.0 + intensity_noise[r])
            out_keep[r] = True
            out_range[r] = distance
            out_intensity[r] = 255.0 * min(1.0, max(0.0, value))
            wx = ox + distance * dx - start_position[0]
            wy = oy + distance * dy - start_position[1]
            wz = oz + distance * dz - start_position[2]
            for c in range(3):
                out_start[r, c] = (
                    start_rotation[0, c] * wx
                    + start_rotation[1, c] * wy
                    + start_rotation[2, c] * wz
                )


#: keep flag, range, intensity, start-frame point and primitive per beam (serial)
_returns = jit(_returns_body)
#: the same with ``prange`` over batches of beams; each beam writes only its own row, so it
#: equals the serial one
_returns_parallel = jit_parallel(_returns_body)
