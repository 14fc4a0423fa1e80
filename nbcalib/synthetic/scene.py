"""Scenes of analytic primitives, with camera and LiDAR textures, and ray casting.

A :class:`Scene` holds flat float64 arrays the numba kernels take as they are: the primitives
(layout in :mod:`nbcalib.kernels.raycast`), the material table (:mod:`nbcalib.synthetic.texture`),
a bounding volume hierarchy over the primitives (:mod:`nbcalib.synthetic.bvh`), and the lighting.
Scenes are built with :class:`~nbcalib.synthetic.builder.SceneBuilder`, or generated from a seed
by :func:`nbcalib.synthetic.scenes.make_scene` (one module per kind in that package):

- ``"room"``: an office-like room (walls of plaster, bricks or panels, tiled or wooden floor,
  ceiling with light panels; posters, whiteboard, door, windows, an exit sign; tables, cabinets,
  shelves with books, boxes, chairs, a pillar, a bin, a ball, potted plants).
- ``"street"``: a straight street (asphalt with lane markings, kerbs and pavements, building
  facades with windows and shop signs, lamp posts, sign poles with retro-reflective signs, trees
  and hedges, parked cars with retro-reflective number plates, bollards, grass beyond).

The world frame is the LiDAR frame at time 0 (``docs/conventions.md``): the rig stands at the
origin, x forward, z up, so the floor or road is at ``z = -sensor_height``. Nothing is placed
within ``clearance`` metres of the origin (horizontally), so the rig, its camera offset and its
nodding motion stay in free space.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nbcalib.kernels import raycast as _rc
from nbcalib.synthetic.effects import TEXTURE_EFFECTS, check_effects
from nbcalib.synthetic.texture import surface_properties

__all__ = [
    "SCENE_KINDS",
    "Lighting",
    "RayHits",
    "Scene",
    "SceneConfig",
]

SCENE_KINDS = ("room", "street")


@dataclass(frozen=True)
class SceneConfig:
    """How to generate a scene.

    Parameters
    ----------
    kind : str
        ``"room"`` or ``"street"``.
    seed : int
        Seed of the layout, colours and textures; the same seed gives the same scene.
    modality_gap : float
        Size of the camera/LiDAR texture gap in [0, 1]: 0 makes the LiDAR reflectivity the
        camera's albedo luminance, 1 the designed differences (:mod:`nbcalib.synthetic.texture`).
    without : tuple of str
        Texture differences switched off, names of
        :data:`~nbcalib.synthetic.effects.TEXTURE_EFFECTS` (none: the full texture model). They
        change what the sensors see, not the scene's layout or materials.
    sensor_height : float or None
        Height of the LiDAR above the floor or road, metres; None: 1.2 (room), 1.6 (street).
    clearance : float
        Horizontal radius around the origin kept free of objects, metres.
    """

    kind: str = "room"
    seed: int = 0
    modality_gap: float = 1.0
    without: tuple[str, ...] = ()
    sensor_height: float | None = None
    clearance: float = 1.5

    def __post_init__(self):
        if self.kind not in SCENE_KINDS:
            raise ValueError(f"scene kind must be one of {SCENE_KINDS}, got {self.kind!r}")
        if not 0.0 <= self.modality_gap <= 1.0:
            raise ValueError(f"modality_gap must be in [0, 1], got {self.modality_gap}")
        object.__setattr__(self, "without", check_effects(self.without, TEXTURE_EFFECTS))
        if self.clearance < 0.5:
            raise ValueError("clearance must be at least 0.5 m")


@dataclass(frozen=True)
class Lighting:
    """Camera lighting of a scene (the LiDAR is its own light source).

    Parameters
    ----------
    sun_direction : tuple of 3 floats
        Unit vector from the scene towards the sun, world frame.
    sun_irradiance : float
        Irradiance of the sun on a surface facing it (0: no sun).
    ambient : float
        Sky or room ambient light; surfaces facing up get all of it, facing down 40 %.
    point_lights : tuple of (x, y, z, power)
        Point lights in the world frame, metres; irradiance ``power * cos / distance**2``.
    sky_top, sky_horizon : tuple of 3 floats
        Linear RGB radiance of the sky at the zenith and at the horizon (rays that hit nothing).
    """

    sun_direction: tuple[float, float, float] = (0.4, 0.3, 0.866)
    sun_irradiance: float = 0.0
    ambient: float = 0.35
    point_lights: tuple[tuple[float, float, float, float], ...] = ()
    sky_top: tuple[float, float, float] = (0.35, 0.5, 0.85)
    sky_horizon: tuple[float, float, float] = (0.8, 0.85, 0.9)


@dataclass(frozen=True)
class RayHits:
    """Nearest hits of a batch of rays (world frame).

    Attributes
    ----------
    t : ndarray of shape (N,), float64
        Distance along the unit ray to the hit, metres; ``inf`` on a miss.
    prim, face : ndarray of shape (N,), int64
        Hit primitive and face id (:mod:`nbcalib.kernels.raycast`); -1 on a miss.
    normal : ndarray of shape (N, 3), float64
        Unit surface normal facing the ray; NaN on a miss.
    surface : ndarray of shape (N, 2), float64
        Surface coordinates of the hit, metres; NaN on a miss.
    """

    t: np.ndarray
    prim: np.ndarray
    face: np.ndarray
    normal: np.ndarray
    surface: np.ndarray

    @property
    def hit(self) -> np.ndarray:
        """``(N,)`` bool: the ray hit something."""
        return self.prim >= 0


@dataclass(frozen=True, eq=False)
class Scene:
    """A scene the ray caster and the texture kernels take as flat arrays.

    Attributes
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        Primitives, layout of :mod:`nbcalib.kernels.raycast`, world frame.
    materials : ndarray of shape (M, MAT_SIZE), float64
        Material table (:mod:`nbcalib.synthetic.texture`).
    names : tuple of str
        A label per primitive ("wall", "tree crown", ...), for inspection.
    bvh_bounds : ndarray of shape (K, 6), float64
        Hierarchy node boxes ``(min xyz, max xyz)``.
    bvh_nodes : ndarray of shape (K, 3), int64
        ``(first child, first primitive, primitive count)``; leaves have a count > 0, and the
        two children of an inner node are ``first child`` and ``first child + 1``.
    bvh_order : ndarray of shape (P,), int64
        Primitive indices in leaf order.
    lighting : Lighting
        Camera lighting.
    modality_gap : float
        Camera/LiDAR texture gap in [0, 1].
    without : tuple of str
        Texture differences switched off (:class:`SceneConfig`); the shading and LiDAR kernels
        and :meth:`surface_properties` take them from here, as the gap.
    kind : str
        ``"room"``, ``"street"`` or ``"custom"``.
    seed : int
        Seed the scene was generated from.
    """

    prims: np.ndarray
    materials: np.ndarray
    names: tuple[str, ...]
    bvh_bounds: np.ndarray
    bvh_nodes: np.ndarray
    bvh_order: np.ndarray
    lighting: Lighting = field(default_factory=Lighting)
    modality_gap: float = 1.0
    without: tuple[str, ...] = ()
    kind: str = "custom"
    seed: int = 0

    def cast(self, origins, directions, *, t_min=0.0, max_range=np.inf, parallel=False) -> RayHits:
        """Nearest hit of each ray (wraps ``nbcalib.kernels.raycast._cast_rays``).

        Parameters
        ----------
        origins, directions : ndarray of shape (N, 3) or (3,), float64
            Ray origins (world frame, metres) and unit directions; one origin may serve all
            rays. Rows with a non-finite value miss.
        t_min : float
            Hits closer than this along the ray are ignored, metres.
        max_range : float
            Hits farther than this are ignored, metres.
        parallel : bool
            Use the ``prange`` kernel (same result as the serial one).

        Returns
        -------
        RayHits
        """
        origins, directions = _rays(origins, directions)
        n = directions.shape[0]
        out_t = np.empty(n)
        out_prim = np.empty(n, dtype=np.int64)
        out_face = np.empty(n, dtype=np.int64)
        out_normal = np.empty((n, 3))
        out_surface = np.empty((n, 2))
        kernel = _rc._cast_rays_parallel if parallel else _rc._cast_rays
        kernel(
            self.prims,
            self.bvh_bounds,
            self.bvh_nodes,
            self.bvh_order,
            origins,
            directions,
            float(t_min),
            float(max_range),
            out_t,
            out_prim,
            out_face,
            out_normal,
            out_surface,
        )
        return RayHits(out_t, out_prim, out_face, out_normal, out_surface)

    def occluded(self, origins, directions, max_t, *, t_min=0.0, parallel=False) -> np.ndarray:
        """Whether anything lies along each ray within ``(t_min, max_t)`` (shadow rays).

        Parameters
        ----------
        origins, directions : ndarray of shape (N, 3), float64
            Ray origins (world frame, metres) and unit directions.
        max_t : ndarray of shape (N,) or float
            Per-ray distance limit, metres (``inf`` for a light at infinity).
        t_min : float
            Hits closer than this are ignored, metres.
        parallel : bool
            Use the ``prange`` kernel.

        Returns
        -------
        ndarray of shape (N,), bool
        """
        origins, directions = _rays(origins, directions)
        n = directions.shape[0]
        max_t = np.ascontiguousarray(np.broadcast_to(max_t, (n,)), dtype=np.float64)
        out = np.empty(n, dtype=np.bool_)
        kernel = _rc._occluded_parallel if parallel else _rc._occluded
        kernel(
            self.prims,
            self.bvh_bounds,
            self.bvh_nodes,
            self.bvh_order,
            origins,
            directions,
            float(t_min),
            max_t,
            out,
        )
        return out

    def surface_properties(self, hits: RayHits, *, footprint=None, parallel=False):
        """Camera albedo and LiDAR reflectivity at hits; see :func:`texture.surface_properties`.

        ``footprint`` (N,) is the size of each pixel or laser spot on the surface, metres.
        """
        return surface_properties(
            self.prims,
            self.materials,
            hits.prim,
            hits.face,
            hits.surface,
            footprint=footprint,
            gap=self.modality_gap,
            without=self.without,
            parallel=parallel,
        )

    def footprint(self, hits: RayHits, directions, angle) -> np.ndarray:
        """Size on the surface of a ray bundle of angular width ``angle`` (rad), metres (N,).

        Widened by the obliquity (at most 1 / 0.15), 0 for misses.
        """
        cos_incidence = np.abs(np.einsum("ni,ni->n", hits.normal, directions))
        with np.errstate(invalid="ignore"):
            size = hits.t * angle / np.maximum(cos_incidence, 0.15)
        return np.where(hits.hit, size, 0.0)


def _rays(origins, directions):
    directions = np.ascontiguousarray(directions, dtype=np.float64)
    if directions.ndim == 1:
        directions = directions[None]
    if directions.ndim != 2 or directions.shape[1] != 3:
        raise ValueError(f"directions must have shape (N, 3), got {directions.shape}")
    origins = np.asarray(origins, dtype=np.float64)
    if origins.shape == (3,):
        origins = np.broadcast_to(origins, directions.shape)
    if origins.shape != directions.shape:
        raise ValueError(f"origins {origins.shape} do not match directions {directions.shape}")
    return np.ascontiguousarray(origins), directions
