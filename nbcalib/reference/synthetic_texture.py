"""Slow, readable reference of the texture kernels in :mod:`nbcalib.kernels.synthetic_texture`.

Plain Python, one hit at a time, written in the vocabulary of procedural textures: ``lerp``,
``smoothstep``, ``fract``, a lattice hash, value noise and fBm, and one small function per
pattern. The semantics are those of the kernel module's docstring; the arithmetic is the same
operation for operation, so the two agree to the last bit on ordinary inputs (the tests allow
``TOL["kernel_vs_reference"]``).
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels import synthetic_texture as tx
from nbcalib.kernels.raycast import PRIM_MATERIAL

__all__ = ["fbm", "material_at", "pattern", "surface_properties", "value_noise"]


def lerp(a, b, t):
    """``a`` at ``t = 0``, ``b`` at ``t = 1``."""
    return a + (b - a) * t


def smoothstep(t):
    """``3 t^2 - 2 t^3`` for ``t`` in [0, 1]."""
    return t * t * (3.0 - 2.0 * t)


def fract(x):
    """Fractional part, in [0, 1) (also for negative ``x``)."""
    return x - math.floor(x)


def lattice_hash(i, j, seed):
    """A number in [0, 1) for each lattice point ``(i, j)`` and seed: a 32-bit integer mix."""
    mask = 2**32 - 1
    h = (i * 374761393 + j * 668265263 + seed * 1442695041) & mask
    h = ((h ^ (h >> 13)) * 1274126177) & mask
    return (h ^ (h >> 16)) / 2**32


def value_noise(x, y, seed):
    """Hash values on the integer lattice, interpolated with smoothstep weights."""
    i, j = math.floor(x), math.floor(y)
    tx_, ty_ = smoothstep(x - i), smoothstep(y - j)
    bottom = lerp(lattice_hash(i, j, seed), lattice_hash(i + 1, j, seed), tx_)
    top = lerp(lattice_hash(i, j + 1, seed), lattice_hash(i + 1, j + 1, seed), tx_)
    return lerp(bottom, top, ty_)


def fade(footprint, feature):
    """How much a detail of size ``feature`` is averaged away by ``footprint``: 0 to 1."""
    return smoothstep(min(1.0, max(0.0, footprint / feature - 0.5)))


def filtered(value, mean, footprint, feature):
    """``value`` blended towards ``mean`` as the footprint outgrows ``feature``."""
    return lerp(value, mean, fade(footprint, feature))


def fbm(x, y, seed, footprint):
    """Four octaves of value noise (octave ``k``: frequency ``2^k``, weight ``2^-(k+1)``)."""
    total = 0.0
    for octave in range(4):
        frequency = 2.0**octave
        noise = value_noise(x * frequency, y * frequency, seed + 101 * octave)
        total += 0.5 ** (octave + 1) * filtered(noise, 0.5, footprint, 1.0 / frequency)
    return total / (0.5 + 0.25 + 0.125 + 0.0625)


def thin_line(x, width):
    """1 within ``width / 2`` of an integer, else 0."""
    return 1.0 if abs(x - math.floor(x + 0.5)) < 0.5 * width else 0.0


# --- one function per pattern: (s, u, scale, seed, footprint) -> (mask m, tone variation v) ---
def _noise(s, u, scale, seed, fw):
    return fbm(s / scale, u / scale, seed, fw / scale), 0.0


def _bricks(s, u, scale, seed, fw):
    """Running bond: odd rows shifted by half a brick (bricks twice as long as high)."""
    row = math.floor(u / scale)
    along = s / (2.0 * scale) + 0.5 * (row % 2)
    mortar = max(thin_line(u / scale, 0.12), thin_line(along, 0.06))
    tone = 0.35 * (lattice_hash(math.floor(along), row, seed) - 0.5)
    return filtered(mortar, 0.17, fw, 0.12 * scale), filtered(tone, 0.0, fw, scale)


def _tiles(s, u, scale, seed, fw):
    grout = max(thin_line(s / scale, 0.04), thin_line(u / scale, 0.04))
    i, j = math.floor(s / scale), math.floor(u / scale)
    alternate = 0.08 if (i + j) % 2 == 0 else -0.08
    tone = 0.25 * (lattice_hash(i, j, seed) - 0.5) + alternate
    return filtered(grout, 0.08, fw, 0.04 * scale), filtered(tone, 0.0, fw, 0.5 * scale)


def _road(s, u, width, seed, fw):
    """Edge lines, a dashed centre line, zebra crossings and arrows (u across, s along)."""
    edge_line = 0.25 < u < 0.40 or width - 0.40 < u < width - 0.25
    centre_line = abs(u - 0.5 * width) < 0.07 and s % 9.0 < 3.0
    zebra = 50.0 < s % 60.0 < 54.0 and u % 1.0 < 0.5 and 0.6 < u < width - 0.6
    arrow = 40.0 < s % 60.0 < 43.0 and abs(u - 0.25 * width) < 0.15
    paint = 1.0 if edge_line or centre_line or zebra or arrow else 0.0
    return filtered(paint, 0.05, fw, 0.6), 0.0


def _text(s, u, scale, seed, fw):
    """Lines of words of 3 x 5-bit glyphs; some words and paragraphs left blank."""
    line = math.floor(u / scale)
    glyph = math.floor(s / (0.6 * scale))
    in_glyph_x = fract(s / (0.6 * scale))
    in_line = fract(u / scale)
    printed = (
        in_line < 0.7
        and lattice_hash(glyph // 6, line, seed + 7) > 0.25  # the word is there
        and lattice_hash(line // 4, 0, seed + 11) > 0.2  # the paragraph is there
        and in_glyph_x <= 0.8  # not the gap between glyphs
        and glyph % 6 != 5  # not the gap between words
    )
    ink = 0.0
    if printed:
        bit_i = int(in_glyph_x / 0.8 * 3.0)
        bit_j = int(in_line / 0.7 * 5.0)
        ink = 1.0 if lattice_hash(glyph * 16 + bit_i, line * 8 + bit_j, seed) > 0.45 else 0.0
    return filtered(ink, 0.22, fw, 0.2 * scale), 0.0


def _planks(s, u, scale, seed, fw):
    plank = math.floor(u / scale)
    grain = filtered(value_noise(s * 0.7, u / scale * 6.0, seed + plank) - 0.5, 0.0, fw, scale / 6)
    gap = thin_line(u / scale, 0.03)
    tone = 0.3 * (lattice_hash(plank, 0, seed) - 0.5) + 0.2 * grain
    return filtered(gap, 0.03, fw, 0.03 * scale), filtered(tone, 0.0, fw, scale)


def _leaves(s, u, scale, seed, fw):
    clusters = fbm(s / scale, u / scale, seed, fw / scale)
    fine = value_noise(s / scale * 6.0, u / scale * 6.0, seed + 3)
    fine = filtered(fine, 0.5, fw, scale / 6.0)
    lit = 1.0 if clusters + 0.3 * fine > 0.62 else 0.0
    return filtered(lit, 0.35, fw, 0.3 * scale), 0.3 * (fine - 0.5)


def _sign(s, u, scale, seed, fw):
    """A square border and a symbol (a bar and a cross-bar) around the sign's centre."""
    x, y = s / scale - 0.5, u / scale - 0.5
    border = 0.40 < max(abs(x), abs(y)) < 0.46
    bar = abs(x) < 0.08 and abs(y) < 0.28
    cross_bar = abs(y - 0.15) < 0.07 and abs(x) < 0.25
    return filtered(1.0 if border or bar or cross_bar else 0.0, 0.25, fw, 0.06 * scale), 0.0


def _windows(s, u, scale, seed, fw):
    """A grid of windows (storeys ``1.2 scale`` high) above the ground floor, mullions in them."""
    x, y = fract(s / scale), fract(u / (1.2 * scale))
    glass = 0.2 < x < 0.8 and 0.3 < y < 0.85 and u > 0.8 * scale
    mullion = abs(x - 0.5) < 0.02 and fw < 0.04 * scale
    lit = lattice_hash(math.floor(s / scale), math.floor(u / (1.2 * scale)), seed) - 0.5
    return filtered(1.0 if glass and not mullion else 0.0, 0.3, fw, 0.3 * scale), 0.3 * lit


def _stripes(s, u, scale, seed, fw):
    return filtered(1.0 if fract(s / scale) < 0.5 else 0.0, 0.5, fw, 0.5 * scale), 0.0


def _checker(s, u, scale, seed, fw):
    even = (math.floor(s / scale) + math.floor(u / scale)) % 2 == 0
    return filtered(1.0 if even else 0.0, 0.5, fw, scale), 0.0


_PATTERNS = {
    tx.NOISE: _noise,
    tx.BRICKS: _bricks,
    tx.TILES: _tiles,
    tx.ROAD: _road,
    tx.TEXT: _text,
    tx.PLANKS: _planks,
    tx.LEAVES: _leaves,
    tx.SIGN: _sign,
    tx.WINDOWS: _windows,
    tx.STRIPES: _stripes,
    tx.CHECKER: _checker,
}


def pattern(kind, s, u, scale, seed, footprint):
    """Pattern mask ``m`` and tone variation ``v`` of pattern ``kind`` (PLAIN: no pattern)."""
    if kind not in _PATTERNS:
        return 0.0, 0.0
    return _PATTERNS[kind](s, u, scale, seed, footprint)


def material_at(prims, materials, i, face, s, u, footprint, gap, off=0):
    """What both sensors see on primitive ``i`` (reference of ``_material_at``, both needed).

    ``off`` is the kernels' bit mask of texture differences switched off (``tx.OFF_*``).

    Returns
    -------
    albedo : tuple of 3 floats
        Linear RGB, in [0, 1].
    reflectivity : float
        LiDAR reflectivity (above 1 only on retro-reflectors).
    dropout : float
        Extra probability of a lost return.
    retro : bool
        The spot is retro-reflective.
    """
    camera_texture = not (off & tx.OFF_CAMERA_TEXTURE)
    lidar_texture = not (off & tx.OFF_LIDAR_TEXTURE)
    designed_materials = not (off & tx.OFF_MATERIALS)
    half_tone = not (off & tx.OFF_ELEMENTS)
    row = materials[int(prims[i, PRIM_MATERIAL])]
    seed = int(row[tx.MAT_SEED]) + 7919 * i + 131 * face
    kind = int(row[tx.MAT_PATTERN])
    m, v = pattern(kind, s, u, row[tx.MAT_SCALE], seed, footprint)
    ns = row[tx.MAT_NOISE_SCALE]
    colour_a = row[tx.MAT_COLOR_A : tx.MAT_COLOR_A + 3]
    colour_b = row[tx.MAT_COLOR_B : tx.MAT_COLOR_B + 3]
    colours = [lerp(float(a), float(b), m) for a, b in zip(colour_a, colour_b)]

    # camera: the two colours blended by the mask, the tone and a camera-only stain texture
    stain_texture = 1.0
    if camera_texture:
        stains = fbm(s / ns, u / ns, seed + 17, footprint / ns)
        stain_texture = 1.0 + row[tx.MAT_CAMERA_NOISE] * (2.0 * stains - 1.0)
    shade = (1.0 + v) * stain_texture
    albedo = tuple(min(1.0, max(0.0, c * shade)) for c in colours)
    luminance = sum(w * c for w, c in zip(tx.LUMA, albedo))

    # LiDAR: the two reflectivities blended by the mask, half the tone, a LiDAR-only texture;
    # without materials, the camera's colours (their luminance) instead of the reflectivities
    paint_texture = 1.0
    if lidar_texture:
        paint = fbm(s / ns, u / ns, seed + 29, footprint / ns)
        paint_texture = 1.0 + row[tx.MAT_LIDAR_NOISE] * (2.0 * paint - 1.0)
    if designed_materials:
        blended = lerp(row[tx.MAT_REFL_A], row[tx.MAT_REFL_B], m)
    else:
        blended = sum(w * c for w, c in zip(tx.LUMA, colours))
    tone = 1.0 + 0.5 * v if half_tone else 1.0 + v
    designed = max(0.0, blended * tone * paint_texture)
    retro = bool(designed_materials and row[tx.MAT_RETRO] > 0.0 and designed > 1.0 and gap > 0.0)
    if not retro:
        designed = min(designed, 1.0)
    reflectivity = (1.0 - gap) * luminance + gap * designed
    on_glass = m if kind == tx.WINDOWS else 1.0  # windows lose returns on the glass only
    dropout = gap * row[tx.MAT_DROPOUT] * on_glass if designed_materials else 0.0
    return albedo, reflectivity, dropout, retro


def surface_properties(prims, materials, prim, face, surface, footprint, gap, off=0):
    """Albedo, reflectivity, dropout and retro flag per hit (reference of ``_surface_properties``).

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The scene's primitives.
    materials : ndarray of shape (M, MAT_SIZE), float64
        The material table.
    prim, face : ndarray of shape (N,), int64
        Hit primitive (-1: a miss) and face.
    surface : ndarray of shape (N, 2), float64
        Surface coordinates of the hits, metres.
    footprint : ndarray of shape (N,), float64
        Pixel or laser spot size on the surface, metres.
    gap : float
        Modality gap in [0, 1].
    off : int
        Bit mask of texture differences switched off (``OFF_*`` of the kernel module).

    Returns
    -------
    albedo : ndarray of shape (N, 3), float64
        NaN for misses.
    reflectivity : ndarray of shape (N,), float64
        NaN for misses.
    dropout : ndarray of shape (N,), float64
        0 for misses.
    retro : ndarray of shape (N,), bool
        False for misses.
    """
    n = len(prim)
    albedo = np.full((n, 3), np.nan)
    reflectivity = np.full(n, np.nan)
    dropout = np.zeros(n)
    retro = np.zeros(n, dtype=bool)
    for r in range(n):
        if prim[r] < 0:
            continue
        albedo[r], reflectivity[r], dropout[r], retro[r] = material_at(
            prims,
            materials,
            int(prim[r]),
            int(face[r]),
            float(surface[r, 0]),
            float(surface[r, 1]),
            float(footprint[r]),
            float(gap),
            off,
        )
    return albedo, reflectivity, dropout, retro
