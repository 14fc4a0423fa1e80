"""Procedural texture kernels of the synthetic rig: what the camera and the LiDAR see on a surface.

The public wrapper is :func:`nbcalib.synthetic.texture.surface_properties` (which also documents
the texture model); :func:`_material_at` is the per-hit helper that the shading
(:mod:`nbcalib.kernels.synthetic_shading`) and LiDAR (:mod:`nbcalib.kernels.synthetic_lidar`)
kernels call. A material is one row of a flat ``(M, MAT_SIZE)`` float64 table:

=======================  ======================================================================
columns                  meaning
=======================  ======================================================================
``MAT_PATTERN``          pattern id (:data:`PLAIN` ... :data:`CHECKER`), shared by both sensors
``MAT_SCALE``            the pattern's feature size, metres
``MAT_COLOR_A:+3``       linear RGB albedo of the background, in [0, 1]
``MAT_COLOR_B:+3``       linear RGB albedo of the pattern
``MAT_REFL_A``           LiDAR reflectivity of the background (above 1 only if retro)
``MAT_REFL_B``           LiDAR reflectivity of the pattern
``MAT_CAMERA_NOISE``     relative amplitude of the camera-only texture
``MAT_LIDAR_NOISE``      relative amplitude of the LiDAR-only texture
``MAT_NOISE_SCALE``      feature size of those single-modality textures, metres
``MAT_SEED``             seed of the pattern and noise (an integer below 1_000_003)
``MAT_DROPOUT``          extra probability of a lost LiDAR return (glass: on the pattern only)
``MAT_RETRO``            1 for a retro-reflector (reflectivity above 1 saturates the LiDAR)
=======================  ======================================================================

Semantics shared with the slow reference :mod:`nbcalib.reference.synthetic_texture`:

- Noise is value noise on the integer lattice with a 32-bit integer hash (:func:`_hash`),
  smoothstep-interpolated; fBm sums four octaves (amplitudes 1/2 ... 1/16, frequencies 1 ... 8,
  octave ``k`` seeded ``seed + 101 k``) and divides by the sum of the amplitudes.
- A detail of size ``feature`` seen through a footprint ``fw`` (pixel or laser spot, metres)
  blends towards its mean by ``smoothstep(clip(fw / feature - 0.5, 0, 1))`` (:func:`_fade`).
- The pattern gives a mask ``m`` and a tone variation ``v``; a hit on primitive ``i``, face ``f``
  uses the seed ``MAT_SEED + 7919 i + 131 f``. The camera albedo is
  ``clip(lerp(A, B, m) (1 + v) (1 + camera_noise (2 fbm(seed + 17) - 1)), 0, 1)`` per channel,
  the designed reflectivity ``max(0, lerp(RA, RB, m) (1 + v / 2) (1 + lidar_noise
  (2 fbm(seed + 29) - 1)))``, clipped to 1 unless retro-reflective (retro needs ``gap > 0``),
  and the LiDAR reflectivity ``(1 - gap) luminance(albedo) + gap designed``.
- ``off`` is a bit mask of modality differences switched off (``nbcalib synth --without``,
  :mod:`nbcalib.synthetic.effects`); 0 is the model above, bit for bit.
  :data:`OFF_CAMERA_TEXTURE`: the camera noise factor ``(1 + camera_noise (...))`` is 1;
  :data:`OFF_LIDAR_TEXTURE`: the LiDAR noise factor is 1; :data:`OFF_ELEMENTS`: the LiDAR tone
  is ``1 + v`` (as the camera's) instead of ``1 + v / 2``; :data:`OFF_MATERIALS`:
  ``lerp(RA, RB, m)`` is replaced by ``luminance(lerp(A, B, m))`` (the camera's colours), no
  spot is retro-reflective and no return is lost on the material (dropout 0).
"""

from __future__ import annotations

import math

import numpy as np
from numba import prange

from nbcalib.kernels._jit import jit, jit_parallel
from nbcalib.kernels.raycast import PRIM_MATERIAL

# --- pattern ids ----------------------------------------------------------------------------
PLAIN = 0  #: no pattern (m = 0)
NOISE = 1  #: smooth blotches (fBm) between A and B: concrete, asphalt, plaster
BRICKS = 2  #: running-bond bricks of ``scale`` height, mortar = B
TILES = 3  #: square tiles of ``scale``, grout = B, tiles vary in tone
ROAD = 4  #: lane markings on a road strip (``u`` across, ``s`` along); paint = B
TEXT = 5  #: text-like glyph blocks of line height ``scale``; ink = B
PLANKS = 6  #: planks of width ``scale`` along ``s`` with grain
LEAVES = 7  #: foliage clusters of size ``scale``; B = lit leaves
SIGN = 8  #: a sign face: border and a central symbol = B
WINDOWS = 9  #: a facade grid of windows (pitch ``scale``), glass = B
STRIPES = 10  #: stripes across ``s`` of period ``scale``, every other stripe = B
CHECKER = 11  #: checkerboard of squares of ``scale``

# --- material table columns -----------------------------------------------------------------
MAT_PATTERN = 0
MAT_SCALE = 1
MAT_COLOR_A = 2  # 3 columns, linear RGB albedo in [0, 1]
MAT_COLOR_B = 5  # 3 columns
MAT_REFL_A = 8
MAT_REFL_B = 9
MAT_CAMERA_NOISE = 10
MAT_LIDAR_NOISE = 11
MAT_NOISE_SCALE = 12
MAT_SEED = 13
MAT_DROPOUT = 14
MAT_RETRO = 15
MAT_SIZE = 16

#: Rec. 709 luminance weights of linear RGB
LUMA = (0.2126, 0.7152, 0.0722)

# --- bits of ``off``: camera/LiDAR texture differences switched off --------------------------
OFF_CAMERA_TEXTURE = 1  #: no camera-only fBm texture
OFF_LIDAR_TEXTURE = 2  #: no LiDAR-only fBm texture
OFF_MATERIALS = 4  #: LiDAR reflectivity pattern = luminance of the camera's colours
OFF_ELEMENTS = 8  #: per-element tone reaches the LiDAR at full strength


# --- noise ----------------------------------------------------------------------------------
@jit
def _hash(i, j, seed):
    """Integer lattice hash to [0, 1) (a 32-bit mix; int64 arithmetic masked to 32 bits)."""
    h = (i * 374761393 + j * 668265263 + seed * 1442695041) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return h / 4294967296.0


@jit
def _value_noise(x, y, seed):
    """Smooth value noise in [0, 1) with unit lattice spacing."""
    fx = math.floor(x)
    fy = math.floor(y)
    i = int(fx)
    j = int(fy)
    tx = x - fx
    ty = y - fy
    tx = tx * tx * (3.0 - 2.0 * tx)
    ty = ty * ty * (3.0 - 2.0 * ty)
    a = _hash(i, j, seed)
    b = _hash(i + 1, j, seed)
    c = _hash(i, j + 1, seed)
    d = _hash(i + 1, j + 1, seed)
    return (a + (b - a) * tx) + ((c + (d - c) * tx) - (a + (b - a) * tx)) * ty


@jit
def _fade(footprint, feature):
    """How much a detail of size ``feature`` is averaged away by a ``footprint``: 0 to 1.

    0 while the footprint is below half the feature, 1 above one and a half features, smooth in
    between: details finer than a pixel (or a laser spot) fade to their mean instead of aliasing.
    """
    x = min(1.0, max(0.0, footprint / feature - 0.5))
    return x * x * (3.0 - 2.0 * x)


@jit
def _fbm(x, y, seed, footprint):
    """Four octaves of value noise in [0, 1); octaves finer than ``footprint`` fade to 0.5."""
    total = 0.0
    amplitude = 0.5
    frequency = 1.0
    norm = 0.0
    for octave in range(4):
        fade = _fade(footprint, 1.0 / frequency)
        value = _value_noise(x * frequency, y * frequency, seed + 101 * octave)
        total += amplitude * (value + (0.5 - value) * fade)
        norm += amplitude
        amplitude *= 0.5
        frequency *= 2.0
    return total / norm


@jit
def _line(x, width):
    """1 within ``width / 2`` of the nearest integer of ``x``, else 0 (a periodic thin line)."""
    return 1.0 if abs(x - math.floor(x + 0.5)) < 0.5 * width else 0.0


@jit
def _filtered(m, mean, footprint, feature):
    """Blend a pattern value towards its mean as the footprint outgrows the feature."""
    return m + (mean - m) * _fade(footprint, feature)


# --- patterns -------------------------------------------------------------------------------
@jit
def _pattern(kind, s, u, scale, seed, fw):
    """Pattern mask ``m`` in [0, 1] and a per-element tone variation ``v`` in about [-0.2, 0.2].

    ``(s, u)`` are surface coordinates and ``fw`` the footprint of the pixel or laser spot,
    metres; details smaller than the footprint fade to their mean (:func:`_fade`).
    """
    if kind == NOISE:
        return _fbm(s / scale, u / scale, seed, fw / scale), 0.0
    if kind == BRICKS:
        row = math.floor(u / scale)
        x = s / (2.0 * scale) + 0.5 * (row % 2)
        mortar = max(_line(u / scale, 0.12), _line(x, 0.06))
        v = 0.35 * (_hash(math.floor(x), int(row), seed) - 0.5)
        return _filtered(mortar, 0.17, fw, 0.12 * scale), _filtered(v, 0.0, fw, scale)
    if kind == TILES:
        grout = max(_line(s / scale, 0.04), _line(u / scale, 0.04))
        i = math.floor(s / scale)
        j = math.floor(u / scale)
        v = 0.25 * (_hash(i, j, seed) - 0.5) + (0.08 if (i + j) % 2 == 0 else -0.08)
        return _filtered(grout, 0.08, fw, 0.04 * scale), _filtered(v, 0.0, fw, 0.5 * scale)
    if kind == ROAD:
        # u across the road (0..width), s along it; scale = road width
        width = scale
        edge = 1.0 if (0.25 < u < 0.40) or (width - 0.40 < u < width - 0.25) else 0.0
        centre = 1.0 if abs(u - 0.5 * width) < 0.07 and (s % 9.0) < 3.0 else 0.0
        crossing = (s % 60.0) > 50.0 and (s % 60.0) < 54.0 and (u % 1.0) < 0.5
        crossing_m = 1.0 if crossing and 0.6 < u < width - 0.6 else 0.0
        arrow = (s % 60.0) > 40.0 and (s % 60.0) < 43.0 and abs(u - 0.25 * width) < 0.15
        m = max(max(edge, centre), max(crossing_m, 1.0 if arrow else 0.0))
        return _filtered(m, 0.05, fw, 0.6), 0.0
    if kind == TEXT:
        line = math.floor(u / scale)
        in_line = (u / scale - line) < 0.7
        # words: runs of glyphs separated by gaps; glyphs are 3 x 5 blocks of 'ink' bits
        glyph = math.floor(s / (0.6 * scale))
        gx = s / (0.6 * scale) - glyph
        gy = (u / scale - line) / 0.7
        word = _hash(int(glyph) // 6, int(line), seed + 7) > 0.25
        paragraph = _hash(int(line) // 4, 0, seed + 11) > 0.2
        if not (in_line and word and paragraph) or gx > 0.8 or int(glyph) % 6 == 5:
            return _filtered(0.0, 0.22, fw, 0.2 * scale), 0.0
        bit_i = int(gx / 0.8 * 3.0)
        bit_j = int(gy * 5.0)
        ink = _hash(int(glyph) * 16 + bit_i, int(line) * 8 + bit_j, seed) > 0.45
        return _filtered(1.0 if ink else 0.0, 0.22, fw, 0.2 * scale), 0.0
    if kind == PLANKS:
        plank = math.floor(u / scale)
        grain = _value_noise(s * 0.7, u / scale * 6.0, seed + int(plank)) - 0.5
        grain = _filtered(grain, 0.0, fw, scale / 6.0)
        gap = _line(u / scale, 0.03)
        v = 0.3 * (_hash(int(plank), 0, seed) - 0.5) + 0.2 * grain
        return _filtered(gap, 0.03, fw, 0.03 * scale), _filtered(v, 0.0, fw, scale)
    if kind == LEAVES:
        n = _fbm(s / scale, u / scale, seed, fw / scale)
        fine = _filtered(
            _value_noise(s / scale * 6.0, u / scale * 6.0, seed + 3), 0.5, fw, scale / 6.0
        )
        m = 1.0 if n + 0.3 * fine > 0.62 else 0.0
        return _filtered(m, 0.35, fw, 0.3 * scale), 0.3 * (fine - 0.5)
    if kind == SIGN:
        # scale = the sign's full width; (s, u) from its corner
        cx = s / scale - 0.5
        cy = u / scale - 0.5
        r = max(abs(cx), abs(cy))
        border = 0.40 < r < 0.46
        symbol = (abs(cx) < 0.08 and abs(cy) < 0.28) or (abs(cy - 0.15) < 0.07 and abs(cx) < 0.25)
        m = 1.0 if border or symbol else 0.0
        return _filtered(m, 0.25, fw, 0.06 * scale), 0.0
    if kind == WINDOWS:
        wx = s / scale - math.floor(s / scale)
        wy = u / (1.2 * scale) - math.floor(u / (1.2 * scale))
        glass = 0.2 < wx < 0.8 and 0.3 < wy < 0.85 and u > 0.8 * scale
        mullion = abs(wx - 0.5) < 0.02 and fw < 0.04 * scale
        j = math.floor(u / (1.2 * scale))
        lit = _hash(math.floor(s / scale), j, seed) - 0.5
        m = 1.0 if glass and not mullion else 0.0
        return _filtered(m, 0.3, fw, 0.3 * scale), 0.3 * lit
    if kind == STRIPES:
        m = 1.0 if (s / scale - math.floor(s / scale)) < 0.5 else 0.0
        return _filtered(m, 0.5, fw, 0.5 * scale), 0.0
    if kind == CHECKER:
        i = math.floor(s / scale)
        j = math.floor(u / scale)
        return _filtered(1.0 if (i + j) % 2 == 0 else 0.0, 0.5, fw, scale), 0.0
    return 0.0, 0.0


@jit
def _clip01(x):
    return min(1.0, max(0.0, x))


@jit
def _material_at(prims, materials, i, face, s, u, fw, gap, off, need_camera, need_lidar):
    """What both sensors see where a ray hit primitive ``i``.

    Returns ``(red, green, blue, reflectivity, dropout, retro)``: the linear albedo in [0, 1],
    the LiDAR reflectivity (above 1 only on retro-reflectors), the extra probability of a lost
    return, and whether the spot is retro-reflective. ``(s, u)`` and the footprint ``fw`` are in
    metres, ``gap`` is the modality gap and ``off`` the bit mask of differences switched off
    (``OFF_*``, module docstring). A modality not needed (``need_camera`` / ``need_lidar``
    False) is skipped and returned as NaN, except that the LiDAR needs the camera's albedo when
    ``gap < 1``.
    """
    row = materials[int(prims[i, PRIM_MATERIAL])]
    seed = int(row[MAT_SEED]) + 7919 * i + 131 * face
    kind = int(row[MAT_PATTERN])
    m, v = _pattern(kind, s, u, row[MAT_SCALE], seed, fw)
    ns = row[MAT_NOISE_SCALE]
    a = MAT_COLOR_A
    b = MAT_COLOR_B
    red = green = blue = reflectivity = np.nan
    luminance = 0.0
    if need_camera or (need_lidar and gap < 1.0):
        camera_tex = 1.0
        if not (off & OFF_CAMERA_TEXTURE):
            noise = _fbm(s / ns, u / ns, seed + 17, fw / ns)
            camera_tex = 1.0 + row[MAT_CAMERA_NOISE] * (2.0 * noise - 1.0)
        shade = (1.0 + v) * camera_tex
        red = _clip01((row[a] + (row[b] - row[a]) * m) * shade)
        green = _clip01((row[a + 1] + (row[b + 1] - row[a + 1]) * m) * shade)
        blue = _clip01((row[a + 2] + (row[b + 2] - row[a + 2]) * m) * shade)
        luminance = LUMA[0] * red + LUMA[1] * green + LUMA[2] * blue
    retro = False
    dropout = 0.0
    if need_lidar:
        lidar_tex = 1.0
        if not (off & OFF_LIDAR_TEXTURE):
            noise = _fbm(s / ns, u / ns, seed + 29, fw / ns)
            lidar_tex = 1.0 + row[MAT_LIDAR_NOISE] * (2.0 * noise - 1.0)
        tone = (1.0 + v) if off & OFF_ELEMENTS else (1.0 + 0.5 * v)
        if off & OFF_MATERIALS:
            # the camera's colour pattern, without its texture and tone
            base = (
                LUMA[0] * (row[a] + (row[b] - row[a]) * m)
                + LUMA[1] * (row[a + 1] + (row[b + 1] - row[a + 1]) * m)
                + LUMA[2] * (row[a + 2] + (row[b + 2] - row[a + 2]) * m)
            )
        else:
            ra = row[MAT_REFL_A]
            base = ra + (row[MAT_REFL_B] - ra) * m
        designed = max(0.0, base * tone * lidar_tex)
        retro = not (off & OFF_MATERIALS) and row[MAT_RETRO] > 0.0 and designed > 1.0 and gap > 0.0
        if not retro:
            designed = min(designed, 1.0)
        reflectivity = (1.0 - gap) * luminance + gap * designed
        if not (off & OFF_MATERIALS):
            # windows drop returns on the glass only; other materials everywhere
            dropout = gap * row[MAT_DROPOUT] * (m if kind == WINDOWS else 1.0)
    return red, green, blue, reflectivity, dropout, retro


def _surface_properties_body(
    prims, materials, prim, face, surface, footprint, gap, off, albedo, reflectivity, dropout, retro
):
    for r in prange(prim.shape[0]):
        i = prim[r]
        if i < 0:
            albedo[r, 0] = np.nan
            albedo[r, 1] = np.nan
            albedo[r, 2] = np.nan
            reflectivity[r] = np.nan
            dropout[r] = 0.0
            retro[r] = False
            continue
        red, green, blue, refl, drop, is_retro = _material_at(
            prims,
            materials,
            i,
            face[r],
            surface[r, 0],
            surface[r, 1],
            footprint[r],
            gap,
            off,
            True,
            True,
        )
        albedo[r, 0] = red
        albedo[r, 1] = green
        albedo[r, 2] = blue
        reflectivity[r] = refl
        dropout[r] = drop
        retro[r] = is_retro


#: albedo, reflectivity, dropout and retro flag per hit (serial); misses get NaN, 0, False
_surface_properties = jit(_surface_properties_body)
#: the same with ``prange`` over hits; each hit writes only its own row, so it equals the serial one
_surface_properties_parallel = jit_parallel(_surface_properties_body)
