"""Slow, readable reference of the LiDAR return kernel in :mod:`nbcalib.kernels.synthetic_lidar`.

One beam at a time: its world ray from the pose of its firing time, the nearest hit from the
brute-force reference ray caster (:func:`nbcalib.reference.raycast.cast_rays`), the reflectivity
from the reference texture (:func:`nbcalib.reference.synthetic_texture.material_at`), then the
noisy range, the reasons a return is lost, and the intensity. The semantics are those of the
kernel module's docstring; like the ray caster's reference, ranges and points agree with the
kernel to ``TOL["raycast_vs_reference"]``.
"""

from __future__ import annotations

import numpy as np

from nbcalib.reference.raycast import cast_rays
from nbcalib.reference.synthetic_texture import material_at

__all__ = ["returns"]


def returns(prims, materials, gap, poses, beams, params, start_pose, *, off=0):
    """Every beam of a scan, the slow way (reference of ``_returns``).

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The scene's primitives, world frame.
    materials : ndarray of shape (M, MAT_SIZE), float64
        The material table.
    gap : float
        Modality gap in [0, 1].
    poses : tuple of 2 arrays
        ``(rotations, positions)``: ``R_world_lidar`` (K, 3, 3) and ``t_world_lidar`` (K, 3),
        metres, at each distinct firing time.
    beams : tuple of 5 arrays
        ``(which, directions_lidar, range_noise, intensity_noise, lost)``, one row per beam: the
        pose it fires from (int64), its unit direction in the LiDAR frame (N, 3), its range error
        (metres), its relative intensity error, and a uniform draw in [0, 1) deciding random
        dropouts.
    params : ndarray of shape (9,), float64
        ``(min_range, max_range, reach, dropout, incidence_exponent, range_exponent,
        reference_range, min_signal, beam_divergence)``.
    start_pose : tuple of 2 arrays
        ``(start_rotation, start_position)``: ``R_world_lidar`` (3, 3) and ``t_world_lidar`` (3,)
        at the scan start, metres.
    off : int
        Bit mask of texture differences switched off (``OFF_*`` of
        :mod:`nbcalib.kernels.synthetic_texture`).

    Returns
    -------
    keep : ndarray of shape (N,), bool
        The beam returned.
    ranges : ndarray of shape (N,), float64
        Noisy range of each kept return, metres; NaN otherwise.
    intensity : ndarray of shape (N,), float64
        Intensity in [0, 255] of each kept return; NaN otherwise.
    points_start : ndarray of shape (N, 3), float64
        Each kept return in the LiDAR frame at the scan start, metres; NaN otherwise.
    prim : ndarray of shape (N,), int64
        Primitive each beam hit (also for lost returns), -1 for none.
    """
    rotations, positions = poses
    which, directions_lidar, range_noise, intensity_noise, lost = beams
    start_rotation, start_position = start_pose
    min_range, max_range, reach, dropout = params[:4]
    incidence_exponent, range_exponent, reference_range, min_signal, divergence = params[4:9]
    n = len(directions_lidar)
    keep = np.zeros(n, dtype=bool)
    ranges = np.full(n, np.nan)
    intensity = np.full(n, np.nan)
    points_start = np.full((n, 3), np.nan)
    prim = np.full(n, -1, dtype=np.int64)
    for r in range(n):
        origin = positions[which[r]]
        direction = rotations[which[r]] @ directions_lidar[r]
        t, hit, face, normal, surface = (
            a[0] for a in cast_rays(prims, origin[None], direction[None], t_max=reach)
        )
        if hit < 0:
            continue
        prim[r] = hit
        cos_incidence = abs(float(normal @ direction))
        footprint = t * divergence / max(cos_incidence, 0.15)
        _, reflectivity, material_dropout, retro = material_at(
            prims, materials, int(hit), int(face), surface[0], surface[1], footprint, gap, off
        )
        distance = t + range_noise[r]
        if not min_range <= distance <= max_range or cos_incidence <= 0.02:
            continue  # out of range, or too grazing to return
        range_term = min(1.0, reference_range / distance) ** range_exponent
        signal = reflectivity * cos_incidence**incidence_exponent * range_term
        if lost[r] < dropout + material_dropout:
            continue  # lost at random, or on glass
        if signal < min_signal and not retro:
            continue  # too weak
        value = 1.0 if retro else min(signal, 1.0)
        keep[r] = True
        ranges[r] = distance
        intensity[r] = 255.0 * min(1.0, max(0.0, value * (1.0 + intensity_noise[r])))
        points_start[r] = start_rotation.T @ (origin + distance * direction - start_position)
    return keep, ranges, intensity, points_start, prim
