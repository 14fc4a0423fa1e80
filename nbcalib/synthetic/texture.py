"""Materials and procedural textures: what the camera and the LiDAR see on a surface.

A material is one row of a flat float64 table (columns ``MAT_*`` of
:mod:`nbcalib.kernels.synthetic_texture`). Both modalities share a
geometric *pattern* (bricks, tiles, lane markings, text-like glyphs, windows, ...) evaluated from
the hit's surface coordinates ``(s, u)`` in metres: the pattern mask ``m`` in [0, 1] blends the
material's colour/reflectivity ``A`` (background) into ``B`` (pattern), so edges line up in both
images. On top of that each modality has its own texture, an fBm value noise with its own seed
(camera-only stains, LiDAR-only paint and wetness), and the per-element variations (one brick
darker than the next) reach the LiDAR only at half strength. Reflectivities above 1 on a material
flagged ``MAT_RETRO`` are retro-reflective (signs, lane paint beads): the LiDAR saturates there.

The *modality gap* ``g`` in [0, 1] scales all this: the LiDAR reflectivity is
``(1 - g) * luminance(albedo) + g * designed_reflectivity``, so ``g = 0`` gives the LiDAR exactly
the camera's albedo texture and ``g = 1`` (default) the designed differences (vegetation dark in
the camera and bright in the LiDAR, glass bright in the camera and weak in the LiDAR, ...).
Shading and shadows are the camera's alone (:mod:`nbcalib.synthetic.render`).

Each of these differences can be switched off on its own (``without``, names of
:data:`nbcalib.synthetic.effects.TEXTURE_EFFECTS`; :mod:`nbcalib.synthetic.effects` says how they
compose with the gap): ``camera-texture`` and ``lidar-texture`` drop one modality's own noise,
``materials`` makes the designed reflectivity the luminance of the camera's colours
``lerp(A, B, m)`` (no inversions, gains, glass dropouts or retro-reflectors), ``elements`` lets
the per-element variation reach the LiDAR at full strength.

The kernels (:mod:`nbcalib.kernels.synthetic_texture`, which lays out the table) are private
and called through :func:`surface_properties`; their slow reference is
:mod:`nbcalib.reference.synthetic_texture`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nbcalib.kernels import synthetic_texture as _tx
from nbcalib.synthetic.effects import TEXTURE_EFFECTS, check_effects

__all__ = ["PATTERNS", "Material", "surface_properties", "texture_bits"]

#: pattern names of :class:`Material` -> pattern ids of the kernels
PATTERNS = {
    "plain": _tx.PLAIN,
    "noise": _tx.NOISE,
    "bricks": _tx.BRICKS,
    "tiles": _tx.TILES,
    "road": _tx.ROAD,
    "text": _tx.TEXT,
    "planks": _tx.PLANKS,
    "leaves": _tx.LEAVES,
    "sign": _tx.SIGN,
    "windows": _tx.WINDOWS,
    "stripes": _tx.STRIPES,
    "checker": _tx.CHECKER,
}


@dataclass(frozen=True)
class Material:
    """One surface material; :meth:`row` packs it into the kernels' table.

    Parameters
    ----------
    pattern : str
        A key of :data:`PATTERNS`, shared by both modalities.
    scale : float
        The pattern's feature size, metres (brick height, tile size, glyph line height, ...).
    color_a, color_b : tuple of 3 floats
        Linear RGB camera albedo of the background and of the pattern, in [0, 1].
    reflectivity_a, reflectivity_b : float
        LiDAR reflectivity of the background and of the pattern, in [0, 1]; above 1 only with
        ``retro=True`` (saturates the LiDAR).
    camera_noise, lidar_noise : float
        Relative amplitude of the texture seen by one modality only, in [0, 1].
    noise_scale : float
        Feature size of those single-modality textures, metres.
    seed : int
        Seed of this material's pattern and noise (primitives add their index).
    dropout : float
        Extra probability that a LiDAR return is lost on this surface (glass, black paint).
    retro : bool
        Retro-reflective: reflectivities above 1 saturate the LiDAR at any incidence.
    """

    pattern: str = "plain"
    scale: float = 1.0
    color_a: tuple[float, float, float] = (0.5, 0.5, 0.5)
    color_b: tuple[float, float, float] = (0.5, 0.5, 0.5)
    reflectivity_a: float = 0.3
    reflectivity_b: float = 0.3
    camera_noise: float = 0.1
    lidar_noise: float = 0.1
    noise_scale: float = 0.5
    seed: int = 0
    dropout: float = 0.0
    retro: bool = False

    def row(self) -> np.ndarray:
        """Pack the material into one ``(MAT_SIZE,)`` float64 row of the kernels' table."""
        if self.pattern not in PATTERNS:
            raise ValueError(f"unknown pattern {self.pattern!r}; expected one of {list(PATTERNS)}")
        if self.scale <= 0 or self.noise_scale <= 0:
            raise ValueError("pattern and noise scales must be positive")
        row = np.zeros(_tx.MAT_SIZE)
        row[_tx.MAT_PATTERN] = PATTERNS[self.pattern]
        row[_tx.MAT_SCALE] = self.scale
        row[_tx.MAT_COLOR_A : _tx.MAT_COLOR_A + 3] = self.color_a
        row[_tx.MAT_COLOR_B : _tx.MAT_COLOR_B + 3] = self.color_b
        row[_tx.MAT_REFL_A] = self.reflectivity_a
        row[_tx.MAT_REFL_B] = self.reflectivity_b
        row[_tx.MAT_CAMERA_NOISE] = self.camera_noise
        row[_tx.MAT_LIDAR_NOISE] = self.lidar_noise
        row[_tx.MAT_NOISE_SCALE] = self.noise_scale
        row[_tx.MAT_SEED] = self.seed % 1_000_003
        row[_tx.MAT_DROPOUT] = self.dropout
        row[_tx.MAT_RETRO] = 1.0 if self.retro else 0.0
        return row


#: texture switches -> bits of the kernels' ``off`` mask
_OFF_BITS = {
    "camera-texture": _tx.OFF_CAMERA_TEXTURE,
    "lidar-texture": _tx.OFF_LIDAR_TEXTURE,
    "materials": _tx.OFF_MATERIALS,
    "elements": _tx.OFF_ELEMENTS,
}


def texture_bits(without) -> int:
    """The kernels' ``off`` bit mask of the texture switches in ``without`` (others ignored).

    Parameters
    ----------
    without : iterable of str
        Names of :data:`nbcalib.synthetic.effects.EFFECTS`; unknown names raise ValueError.

    Returns
    -------
    int
        0 when no texture switch is listed (the full texture model).
    """
    off = 0
    for name in check_effects(without):
        off |= _OFF_BITS.get(name, 0)
    return off


def surface_properties(
    prims, materials, prim, face, surface, *, footprint=None, gap=1.0, without=(), parallel=False
):
    """Camera albedo and LiDAR reflectivity at ray hits (wraps the texture kernel).

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The scene's primitives (:mod:`nbcalib.kernels.raycast` layout).
    materials : ndarray of shape (M, MAT_SIZE), float64
        The material table.
    prim, face : ndarray of shape (N,), int64
        Hit primitive (-1 for a miss) and face, as returned by the ray caster.
    surface : ndarray of shape (N, 2), float64
        Surface coordinates of the hits, metres.
    footprint : ndarray of shape (N,), float64, optional
        Size of the pixel or laser spot on the surface, metres; pattern details and noise
        octaves finer than it fade to their mean (antialiasing). None: 0 (no filtering).
    gap : float
        Modality gap in [0, 1] (module docstring).
    without : tuple of str
        Texture differences switched off, names of
        :data:`~nbcalib.synthetic.effects.TEXTURE_EFFECTS` (module docstring).
    parallel : bool
        Use the ``prange`` kernel (rows are independent: same result as the serial one).

    Returns
    -------
    albedo : ndarray of shape (N, 3), float64
        Linear RGB albedo in [0, 1]; NaN for misses.
    reflectivity : ndarray of shape (N,), float64
        LiDAR reflectivity, in [0, 1] except on retro-reflectors (up to a few); NaN for misses.
    dropout : ndarray of shape (N,), float64
        Extra probability of a lost return at the hit, in [0, 1].
    retro : ndarray of shape (N,), bool
        The hit is on a retro-reflector (the LiDAR saturates).
    """
    if not 0.0 <= gap <= 1.0:
        raise ValueError(f"gap must be in [0, 1], got {gap}")
    off = texture_bits(check_effects(without, TEXTURE_EFFECTS))
    prim = np.ascontiguousarray(prim, dtype=np.int64)
    face = np.ascontiguousarray(face, dtype=np.int64)
    surface = np.ascontiguousarray(surface, dtype=np.float64)
    n = prim.shape[0]
    if face.shape != (n,) or surface.shape != (n, 2):
        raise ValueError("prim, face and surface must have shapes (N,), (N,) and (N, 2)")
    if n and prim.max() >= len(prims):
        raise ValueError("primitive index out of range")
    if footprint is None:
        footprint = np.zeros(n)
    footprint = np.ascontiguousarray(np.broadcast_to(footprint, (n,)), dtype=np.float64)
    albedo = np.empty((n, 3))
    reflectivity = np.empty(n)
    dropout = np.empty(n)
    retro = np.empty(n, dtype=np.bool_)
    kernel = _tx._surface_properties_parallel if parallel else _tx._surface_properties
    kernel(
        np.ascontiguousarray(prims, dtype=np.float64),
        np.ascontiguousarray(materials, dtype=np.float64),
        prim,
        face,
        surface,
        footprint,
        float(gap),
        off,
        albedo,
        reflectivity,
        dropout,
        retro,
    )
    return albedo, reflectivity, dropout, retro
