"""Procedural scenes of analytic primitives, with camera and LiDAR textures, and ray casting.

A :class:`Scene` holds flat float64 arrays the numba kernels take as they are: the primitives
(layout in :mod:`nbcalib.kernels.raycast`), the material table (:mod:`nbcalib.synthetic.texture`),
a bounding volume hierarchy over the primitives, and the lighting. Scenes are built with
:class:`SceneBuilder`, or generated from a seed by :func:`make_scene`:

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

import math
from dataclasses import dataclass, field

import numpy as np

from nbcalib.kernels import raycast as _rc
from nbcalib.synthetic.texture import MAT_SIZE, Material, surface_properties

__all__ = [
    "SCENE_KINDS",
    "Lighting",
    "RayHits",
    "Scene",
    "SceneBuilder",
    "SceneConfig",
    "build_bvh",
    "make_scene",
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
    sensor_height : float or None
        Height of the LiDAR above the floor or road, metres; None: 1.2 (room), 1.6 (street).
    clearance : float
        Horizontal radius around the origin kept free of objects, metres.
    """

    kind: str = "room"
    seed: int = 0
    modality_gap: float = 1.0
    sensor_height: float | None = None
    clearance: float = 1.5

    def __post_init__(self):
        if self.kind not in SCENE_KINDS:
            raise ValueError(f"scene kind must be one of {SCENE_KINDS}, got {self.kind!r}")
        if not 0.0 <= self.modality_gap <= 1.0:
            raise ValueError(f"modality_gap must be in [0, 1], got {self.modality_gap}")
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


# --- building scenes ------------------------------------------------------------------------
def _rotation_z(angle: float) -> np.ndarray:
    """Rows = local axes in the world for a rotation of ``angle`` radians about world z."""
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def _orthonormal_rows(x_axis, y_axis) -> np.ndarray:
    x = np.asarray(x_axis, dtype=np.float64)
    x = x / np.linalg.norm(x)
    y = np.asarray(y_axis, dtype=np.float64)
    y = y - (y @ x) * x
    y = y / np.linalg.norm(y)
    return np.stack([x, y, np.cross(x, y)])


class SceneBuilder:
    """Collects primitives and materials, then packs them into a :class:`Scene`.

    Every ``add`` method returns the new primitive's index. ``material`` is a :class:`Material`
    (added to the table) or the index of one added before with :meth:`material`.
    """

    def __init__(self):
        self._prims: list[np.ndarray] = []
        self._materials: list[np.ndarray] = []
        self._names: list[str] = []

    def material(self, material: Material) -> int:
        """Add a material to the table; returns its index."""
        self._materials.append(material.row())
        return len(self._materials) - 1

    def _add(self, kind, center, rows, half, material, name) -> int:
        if isinstance(material, Material):
            material = self.material(material)
        if not 0 <= int(material) < len(self._materials):
            raise ValueError(f"unknown material index {material}")
        half = np.asarray(half, dtype=np.float64)
        if np.any(half < 0) or not np.all(np.isfinite(half)):
            raise ValueError(f"half-extents must be finite and >= 0, got {half}")
        row = np.zeros(_rc.PRIM_SIZE)
        row[_rc.PRIM_TYPE] = kind
        row[_rc.PRIM_MATERIAL] = int(material)
        row[_rc.PRIM_CENTER : _rc.PRIM_CENTER + 3] = center
        row[_rc.PRIM_AXES : _rc.PRIM_AXES + 9] = np.asarray(rows, dtype=np.float64).ravel()
        row[_rc.PRIM_HALF : _rc.PRIM_HALF + 3] = half
        self._prims.append(row)
        self._names.append(name)
        return len(self._prims) - 1

    def rectangle(self, center, x_axis, y_axis, half_size, material, *, name="rectangle") -> int:
        """A two-sided rectangle: ``|x| <= a`` along ``x_axis``, ``|y| <= b`` along ``y_axis``.

        ``y_axis`` is made orthogonal to ``x_axis``; the normal is ``x_axis x y_axis``. Surface
        coordinates run from the corner ``-a x_axis - b y_axis``.
        """
        a, b = half_size
        return self._add(
            _rc.RECTANGLE, center, _orthonormal_rows(x_axis, y_axis), (a, b, 0.0), material, name
        )

    def box(self, center, half_size, material, *, yaw=0.0, name="box") -> int:
        """A box with half-extents ``(a, b, c)``, turned by ``yaw`` radians about world z."""
        return self._add(_rc.BOX, center, _rotation_z(yaw), half_size, material, name)

    def cylinder(self, center, radius, half_height, material, *, axis=(0, 0, 1), name="cylinder"):
        """A capped cylinder around ``axis`` (through ``center``), ``|height| <= half_height``."""
        axis = np.asarray(axis, dtype=np.float64)
        axis = axis / np.linalg.norm(axis)
        helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = np.cross(helper, axis)
        rows = np.stack([x / np.linalg.norm(x), np.cross(axis, x / np.linalg.norm(x)), axis])
        return self._add(_rc.CYLINDER, center, rows, (radius, radius, half_height), material, name)

    def ellipsoid(self, center, semi_axes, material, *, yaw=0.0, name="ellipsoid") -> int:
        """An ellipsoid with semi-axes ``(a, b, c)``, turned by ``yaw`` radians about world z."""
        if min(semi_axes) <= 0:
            raise ValueError("ellipsoid semi-axes must be positive")
        return self._add(_rc.ELLIPSOID, center, _rotation_z(yaw), semi_axes, material, name)

    def sphere(self, center, radius, material, *, name="sphere") -> int:
        """A sphere (an ellipsoid with equal semi-axes)."""
        return self.ellipsoid(center, (radius, radius, radius), material, name=name)

    def build(self, *, lighting=None, modality_gap=1.0, kind="custom", seed=0) -> Scene:
        """Pack everything into a :class:`Scene` (and build its hierarchy)."""
        if not self._prims:
            raise ValueError("a scene needs at least one primitive")
        prims = np.ascontiguousarray(np.stack(self._prims))
        bounds, nodes, order = build_bvh(prims)
        return Scene(
            prims=prims,
            materials=np.ascontiguousarray(np.stack(self._materials).reshape(-1, MAT_SIZE)),
            names=tuple(self._names),
            bvh_bounds=bounds,
            bvh_nodes=nodes,
            bvh_order=order,
            lighting=lighting if lighting is not None else Lighting(),
            modality_gap=float(modality_gap),
            kind=kind,
            seed=int(seed),
        )


def primitive_bounds(prims) -> tuple[np.ndarray, np.ndarray]:
    """Axis-aligned world boxes ``(lo, hi)``, each ``(P, 3)``, enclosing every primitive."""
    prims = np.asarray(prims, dtype=np.float64)
    center = prims[:, _rc.PRIM_CENTER : _rc.PRIM_CENTER + 3]
    rows = prims[:, _rc.PRIM_AXES : _rc.PRIM_AXES + 9].reshape(-1, 3, 3)
    half = prims[:, _rc.PRIM_HALF : _rc.PRIM_HALF + 3]
    # extent along world k of sum_j h_j axis_j: sum_j |axis_j[k]| h_j
    extent = np.einsum("pjk,pj->pk", np.abs(rows), half)
    pad = 1e-6 * (1.0 + np.abs(center).max(axis=1, keepdims=True))
    return center - extent - pad, center + extent + pad


def _area(lo, hi):
    """Surface areas of boxes ``(lo, hi)`` of shape (..., 3)."""
    d = np.maximum(hi - lo, 0.0)
    return 2.0 * (d[..., 0] * d[..., 1] + d[..., 1] * d[..., 2] + d[..., 2] * d[..., 0])


def _best_split(lo, hi, centroid):
    """Surface-area-heuristic split of a set of boxes: ``(cost, order, count_left)``.

    For each axis, the boxes sorted by centroid are split at every position; the cost of a
    split is ``area(left) * n_left + area(right) * n_right`` (expected intersection tests).
    """
    n = len(lo)
    best = (np.inf, None, 0)
    for axis in range(3):
        order = np.argsort(centroid[:, axis], kind="stable")
        l_lo = np.minimum.accumulate(lo[order], axis=0)
        l_hi = np.maximum.accumulate(hi[order], axis=0)
        r_lo = np.minimum.accumulate(lo[order][::-1], axis=0)[::-1]
        r_hi = np.maximum.accumulate(hi[order][::-1], axis=0)[::-1]
        counts = np.arange(1, n)
        cost = _area(l_lo[:-1], l_hi[:-1]) * counts + _area(r_lo[1:], r_hi[1:]) * (n - counts)
        k = int(np.argmin(cost))
        if cost[k] < best[0]:
            best = (float(cost[k]), order, k + 1)
    return best


def build_bvh(prims, *, leaf_size: int = 1):
    """Bounding volume hierarchy over the primitives, split by the surface area heuristic.

    Parameters
    ----------
    prims : ndarray of shape (P, PRIM_SIZE), float64
        The primitives.
    leaf_size : int
        Leaves hold at most this many primitives (more only when no split helps).

    Returns
    -------
    bounds : ndarray of shape (K, 6), float64
        Node boxes ``(min xyz, max xyz)``, world frame.
    nodes : ndarray of shape (K, 3), int64
        ``(first child, first primitive, primitive count)`` per node; root = node 0.
    order : ndarray of shape (P,), int64
        Primitive indices in leaf order.
    """
    lo, hi = primitive_bounds(prims)
    centroid = 0.5 * (lo + hi)
    bounds: list[np.ndarray] = [np.zeros(6)]
    nodes: list[list[int]] = [[0, 0, 0]]
    order: list[int] = []

    def fill(node: int, members: np.ndarray) -> None:
        box_lo, box_hi = lo[members].min(axis=0), hi[members].max(axis=0)
        bounds[node] = np.concatenate([box_lo, box_hi])
        if len(members) > leaf_size:
            cost, sorted_idx, n_left = _best_split(lo[members], hi[members], centroid[members])
            # split when descending (two box tests, then the children's expected primitive
            # tests) is cheaper than testing every member, and always for large sets
            area = _area(box_lo, box_hi)
            if cost + 2.0 * area < len(members) * area or len(members) > 8:
                members = members[sorted_idx]
                first = len(nodes)
                bounds.extend([np.zeros(6), np.zeros(6)])
                nodes.extend([[0, 0, 0], [0, 0, 0]])
                nodes[node] = [first, 0, 0]
                fill(first, members[:n_left])
                fill(first + 1, members[n_left:])
                return
        nodes[node] = [-1, len(order), len(members)]
        order.extend(int(m) for m in members)

    fill(0, np.arange(len(prims)))
    return (
        np.ascontiguousarray(np.stack(bounds)),
        np.ascontiguousarray(np.array(nodes, dtype=np.int64)),
        np.ascontiguousarray(np.array(order, dtype=np.int64)),
    )


# --- procedural generators ------------------------------------------------------------------
def make_scene(config: SceneConfig | None = None, **overrides) -> Scene:
    """Generate a room or a street from a seed.

    Parameters
    ----------
    config : SceneConfig, optional
        Kind, seed, modality gap; keyword overrides replace its fields
        (``make_scene(kind="street", seed=3)``).

    Returns
    -------
    Scene
    """
    config = SceneConfig(**{**(config.__dict__ if config else {}), **overrides})
    rng = np.random.default_rng([config.seed, 0x5CE7E])
    if config.kind == "room":
        return _make_room(config, rng)
    return _make_street(config, rng)


class _Placer:
    """Rejection sampling of object footprints (circles) that keep clear of each other."""

    def __init__(self, rng, clearance):
        self.rng = rng
        self.taken: list[tuple[float, float, float]] = [(0.0, 0.0, clearance)]

    def free(self, x, y, r) -> bool:
        return all(math.hypot(x - a, y - b) >= r + c for a, b, c in self.taken)

    def take(self, x, y, r) -> None:
        self.taken.append((x, y, r))

    def place(self, x_range, y_range, r, *, tries=40):
        for _ in range(tries):
            x = self.rng.uniform(*x_range)
            y = self.rng.uniform(*y_range)
            if self.free(x, y, r):
                self.take(x, y, r)
                return x, y
        return None


def _jitter(rng, color, amount=0.08):
    c = np.asarray(color) * (1.0 + rng.uniform(-amount, amount, 3))
    return tuple(float(v) for v in np.clip(c, 0.0, 1.0))


def _seed(rng) -> int:
    return int(rng.integers(0, 1_000_000))


def _wall_material(rng) -> Material:
    choice = rng.integers(0, 4)
    if choice == 0:  # painted plaster: stains for the camera, a different blotch for the LiDAR
        paint = _jitter(
            rng, [(0.75, 0.72, 0.66), (0.62, 0.68, 0.72), (0.78, 0.74, 0.55)][rng.integers(3)]
        )
        return Material(
            "noise",
            1.5,
            paint,
            _jitter(rng, paint, 0.15),
            0.55,
            0.6,
            camera_noise=0.12,
            lidar_noise=0.2,
            noise_scale=0.4,
            seed=_seed(rng),
        )
    if choice == 1:  # bricks
        return Material(
            "bricks",
            0.075,
            _jitter(rng, (0.42, 0.17, 0.1)),
            (0.55, 0.54, 0.5),
            0.35,
            0.45,
            camera_noise=0.15,
            lidar_noise=0.15,
            noise_scale=0.3,
            seed=_seed(rng),
        )
    if choice == 2:  # wooden panels
        return Material(
            "planks",
            0.3,
            _jitter(rng, (0.5, 0.34, 0.2)),
            (0.2, 0.13, 0.08),
            0.5,
            0.2,
            camera_noise=0.1,
            lidar_noise=0.1,
            noise_scale=0.5,
            seed=_seed(rng),
        )
    # concrete
    return Material(
        "noise",
        0.8,
        (0.5, 0.5, 0.48),
        (0.36, 0.36, 0.35),
        0.4,
        0.3,
        camera_noise=0.15,
        lidar_noise=0.25,
        noise_scale=0.2,
        seed=_seed(rng),
    )


def _poster_material(rng) -> Material:
    kind = rng.integers(0, 4)
    paper = _jitter(rng, (0.85, 0.84, 0.8), 0.05)
    if kind == 0:  # printed text: ink nearly transparent to the LiDAR's infrared
        ink = _jitter(rng, (0.05, 0.05, 0.1), 0.3)
        return Material(
            "text",
            0.06,
            paper,
            ink,
            0.8,
            0.65,
            camera_noise=0.02,
            lidar_noise=0.05,
            seed=_seed(rng),
        )
    if kind == 1:  # a checkerboard poster (bright in both)
        return Material(
            "checker",
            0.08,
            paper,
            (0.04, 0.04, 0.04),
            0.85,
            0.1,
            camera_noise=0.02,
            lidar_noise=0.05,
            seed=_seed(rng),
        )
    if kind == 2:  # a picture: colourful blotches the LiDAR hardly sees
        colour = tuple(float(v) for v in rng.uniform(0.05, 0.8, 3))
        return Material(
            "noise",
            0.12,
            colour,
            _jitter(rng, (0.7, 0.3, 0.1), 0.5),
            0.6,
            0.55,
            camera_noise=0.3,
            lidar_noise=0.05,
            noise_scale=0.05,
            seed=_seed(rng),
        )
    # IR-absorbing print: invisible to the camera, written in the LiDAR image
    return Material(
        "text", 0.1, paper, paper, 0.8, 0.1, camera_noise=0.03, lidar_noise=0.05, seed=_seed(rng)
    )


def _leaves(rng) -> Material:
    dark = _jitter(rng, (0.04, 0.12, 0.03), 0.2)
    lit = _jitter(rng, (0.1, 0.28, 0.06), 0.2)
    return Material(
        "leaves",
        0.25,
        dark,
        lit,
        0.65,
        0.85,
        camera_noise=0.2,
        lidar_noise=0.2,
        noise_scale=0.1,
        seed=_seed(rng),
    )


def _retro_sign(rng, colour=None) -> Material:
    colour = colour or [(0.8, 0.05, 0.03), (0.05, 0.2, 0.7), (0.05, 0.5, 0.1)][rng.integers(3)]
    return Material(
        "sign",
        0.6,
        _jitter(rng, colour, 0.1),
        (0.9, 0.9, 0.88),
        4.0,
        0.9,
        camera_noise=0.03,
        lidar_noise=0.05,
        seed=_seed(rng),
        retro=True,
    )


def _make_room(config: SceneConfig, rng) -> Scene:
    b = SceneBuilder()
    h = 1.2 if config.sensor_height is None else config.sensor_height
    size_x, size_y = rng.uniform(8.0, 12.0), rng.uniform(6.0, 9.0)
    height = rng.uniform(2.8, 3.5)
    # the rig is off-centre, at least 2.5 m from every wall
    cx = rng.uniform(-(size_x / 2 - 2.5), size_x / 2 - 2.5)
    cy = rng.uniform(-(size_y / 2 - 2.5), size_y / 2 - 2.5)
    x0, x1, y0, y1 = cx - size_x / 2, cx + size_x / 2, cy - size_y / 2, cy + size_y / 2
    z0, z1 = -h, height - h
    zc = 0.5 * (z0 + z1)
    up = (0.0, 0.0, 1.0)

    floor = (
        Material(
            "tiles",
            rng.uniform(0.4, 0.6),
            _jitter(rng, (0.55, 0.52, 0.47)),
            (0.3, 0.3, 0.3),
            0.45,
            0.25,
            camera_noise=0.1,
            lidar_noise=0.2,
            noise_scale=0.25,
            seed=_seed(rng),
        )
        if rng.random() < 0.5
        else Material(
            "planks",
            0.18,
            _jitter(rng, (0.45, 0.3, 0.17)),
            (0.15, 0.1, 0.06),
            0.45,
            0.2,
            camera_noise=0.1,
            lidar_noise=0.15,
            noise_scale=0.3,
            seed=_seed(rng),
        )
    )
    b.rectangle(
        ((x0 + x1) / 2, (y0 + y1) / 2, z0),
        (1, 0, 0),
        (0, 1, 0),
        (size_x / 2, size_y / 2),
        floor,
        name="floor",
    )
    ceiling = Material(
        "tiles",
        0.6,
        (0.8, 0.8, 0.78),
        (0.55, 0.55, 0.55),
        0.7,
        0.5,
        camera_noise=0.05,
        lidar_noise=0.1,
        seed=_seed(rng),
    )
    b.rectangle(
        ((x0 + x1) / 2, (y0 + y1) / 2, z1),
        (1, 0, 0),
        (0, 1, 0),
        (size_x / 2, size_y / 2),
        ceiling,
        name="ceiling",
    )

    # walls: (centre, along-wall axis, inward normal, half length)
    walls = [
        ((x1, (y0 + y1) / 2), (0.0, 1.0), (-1.0, 0.0), size_y / 2),
        ((x0, (y0 + y1) / 2), (0.0, -1.0), (1.0, 0.0), size_y / 2),
        (((x0 + x1) / 2, y1), (-1.0, 0.0), (0.0, -1.0), size_x / 2),
        (((x0 + x1) / 2, y0), (1.0, 0.0), (0.0, 1.0), size_x / 2),
    ]
    light_panel = Material(
        "plain",
        1.0,
        (1.0, 1.0, 0.97),
        (1.0, 1.0, 0.97),
        0.7,
        0.7,
        camera_noise=0.0,
        lidar_noise=0.05,
        seed=_seed(rng),
    )
    lights = []
    for gx in np.linspace(x0, x1, 5)[1:-1]:
        for gy in np.linspace(y0, y1, 4)[1:-1]:
            b.rectangle(
                (gx, gy, z1 - 0.01),
                (1, 0, 0),
                (0, 1, 0),
                (0.6, 0.3),
                light_panel,
                name="light panel",
            )
    # two lights cast the shadows (each costs the renderer one shadow ray per pixel)
    for gx in np.linspace(x0, x1, 4)[1:-1]:
        lights.append((float(gx), float(0.5 * (y0 + y1)), float(z1 - 0.3), 4.0))

    for (wx, wy), (ax, ay), (nx, ny), half_len in walls:
        along = (ax, ay, 0.0)
        b.rectangle(
            (wx, wy, zc), along, up, (half_len, height / 2), _wall_material(rng), name="wall"
        )
        # skirting board: a thin box along the wall
        b.box(
            (wx + 0.01 * nx, wy + 0.01 * ny, z0 + 0.05),
            (half_len if ax else 0.01, 0.01 if ax else half_len, 0.05),
            Material(
                "plain", 1.0, (0.15, 0.14, 0.13), (0.15, 0.14, 0.13), 0.2, 0.2, seed=_seed(rng)
            ),
            name="skirting",
        )
        # wall items at positions along the wall, each a rectangle just in front of it
        positions = np.sort(rng.uniform(-half_len + 0.8, half_len - 0.8, rng.integers(4, 8)))
        last = -np.inf
        for p in positions:
            kind = rng.choice(["poster", "poster", "board", "door", "window", "sign"])
            width = {
                "poster": rng.uniform(0.5, 1.2),
                "board": rng.uniform(1.2, 2.0),
                "door": 0.9,
                "window": rng.uniform(1.0, 1.8),
                "sign": 0.35,
            }[kind]
            if p - width / 2 < last + 0.2 or abs(p) + width / 2 > half_len - 0.1:
                continue
            last = p + width / 2
            centre_xy = np.array([wx, wy]) + p * np.array([ax, ay]) + 0.01 * np.array([nx, ny])
            if kind == "poster":
                w2, h2, zm = width / 2, rng.uniform(0.3, 0.6), rng.uniform(1.4, 1.9)
                material = _poster_material(rng)
            elif kind == "board":
                w2, h2, zm = width / 2, 0.55, 1.45
                material = Material(
                    "text",
                    0.09,
                    (0.92, 0.92, 0.92),
                    (0.1, 0.15, 0.5),
                    0.8,
                    0.7,
                    camera_noise=0.05,
                    lidar_noise=0.05,
                    seed=_seed(rng),
                )
            elif kind == "door":
                w2, h2, zm = 0.45, 1.02, 1.02
                material = Material(
                    "planks",
                    0.15,
                    _jitter(rng, (0.35, 0.22, 0.12)),
                    (0.2, 0.12, 0.07),
                    0.45,
                    0.25,
                    camera_noise=0.1,
                    lidar_noise=0.1,
                    seed=_seed(rng),
                )
            elif kind == "window":
                w2, h2, zm = width / 2, 0.6, 1.6
                material = Material(
                    "stripes",
                    width / 2,
                    (0.85, 0.9, 0.95),
                    (0.8, 0.85, 0.92),
                    0.03,
                    0.03,
                    camera_noise=0.15,
                    lidar_noise=0.0,
                    noise_scale=0.3,
                    seed=_seed(rng),
                    dropout=0.7,
                )
            else:
                w2, h2, zm = 0.175, 0.09, 2.3
                material = _retro_sign(rng, (0.05, 0.55, 0.15))
            b.rectangle(
                (centre_xy[0], centre_xy[1], z0 + min(zm, height - h2 - 0.05)),
                along,
                up,
                (w2, h2),
                material,
                name=kind,
            )

    placer = _Placer(rng, config.clearance)
    inner_x = (x0 + 0.8, x1 - 0.8)
    inner_y = (y0 + 0.8, y1 - 0.8)

    def wood() -> Material:
        return Material(
            "planks",
            0.12,
            _jitter(rng, (0.5, 0.35, 0.2)),
            (0.3, 0.2, 0.12),
            0.5,
            0.35,
            camera_noise=0.1,
            lidar_noise=0.1,
            seed=_seed(rng),
        )

    metal = Material(
        "noise",
        0.3,
        (0.35, 0.35, 0.37),
        (0.5, 0.5, 0.52),
        0.4,
        0.45,
        camera_noise=0.05,
        lidar_noise=0.1,
        seed=_seed(rng),
    )
    metal_id = b.material(metal)
    # a rug on the floor (a pattern for both sensors, softer for the LiDAR)
    rug = placer.place(inner_x, inner_y, 0.8, tries=20)
    if rug is not None:
        turn = rng.uniform(0, np.pi)
        b.rectangle(
            (rug[0], rug[1], z0 + 0.005),
            (math.cos(turn), math.sin(turn), 0.0),
            (-math.sin(turn), math.cos(turn), 0.0),
            rng.uniform(0.6, 1.2, 2),
            Material(
                str(rng.choice(["stripes", "checker", "noise"])),
                rng.uniform(0.15, 0.4),
                _jitter(rng, (0.6, 0.15, 0.1), 0.5),
                _jitter(rng, (0.8, 0.75, 0.6), 0.2),
                0.55,
                0.7,
                camera_noise=0.15,
                lidar_noise=0.15,
                noise_scale=0.1,
                seed=_seed(rng),
            ),
            name="rug",
        )
    # tables with legs
    for _ in range(rng.integers(2, 5)):
        spot = placer.place(inner_x, inner_y, 1.1)
        if spot is None:
            continue
        x, y = spot
        yaw = rng.uniform(0, np.pi)
        la, lb = rng.uniform(0.6, 0.9), rng.uniform(0.35, 0.5)
        b.box((x, y, z0 + 0.74), (la, lb, 0.02), wood(), yaw=yaw, name="table top")
        c, s = math.cos(yaw), math.sin(yaw)
        for sa in (-1, 1):
            for sb in (-1, 1):
                lx, ly = sa * (la - 0.06), sb * (lb - 0.06)
                b.cylinder(
                    (x + c * lx - s * ly, y + s * lx + c * ly, z0 + 0.36),
                    0.025,
                    0.36,
                    metal_id,
                    name="table leg",
                )
        # things on the table: a box and a ball
        b.box(
            (x, y, z0 + 0.76 + 0.08),
            (0.15, 0.1, 0.08),
            Material(
                "noise",
                0.2,
                _jitter(rng, (0.55, 0.4, 0.25)),
                (0.4, 0.3, 0.2),
                0.75,
                0.7,
                camera_noise=0.1,
                lidar_noise=0.1,
                seed=_seed(rng),
            ),
            yaw=rng.uniform(0, np.pi),
            name="box",
        )
    # cabinets and shelves along the walls
    for _ in range(rng.integers(4, 8)):
        side = rng.integers(4)
        depth = 0.25
        if side < 2:
            x = x1 - depth - 0.02 if side == 0 else x0 + depth + 0.02
            y = rng.uniform(y0 + 1.0, y1 - 1.0)
            half = (depth, rng.uniform(0.4, 0.9))
        else:
            y = y1 - depth - 0.02 if side == 2 else y0 + depth + 0.02
            x = rng.uniform(x0 + 1.0, x1 - 1.0)
            half = (rng.uniform(0.4, 0.9), depth)
        if not placer.free(x, y, max(half)):
            continue
        placer.take(x, y, max(half))
        tall = rng.uniform(0.8, 2.0)
        if rng.random() < 0.5:
            b.box((x, y, z0 + tall / 2), (half[0], half[1], tall / 2), wood(), name="cabinet")
        else:  # a shelf of books: colourful for the camera, much the same for the LiDAR
            b.box(
                (x, y, z0 + tall / 2),
                (half[0], half[1], tall / 2),
                Material(
                    "stripes",
                    0.04,
                    _jitter(rng, (0.7, 0.2, 0.1), 0.6),
                    _jitter(rng, (0.1, 0.3, 0.6), 0.6),
                    0.5,
                    0.45,
                    camera_noise=0.3,
                    lidar_noise=0.1,
                    noise_scale=0.03,
                    seed=_seed(rng),
                ),
                name="bookshelf",
            )
    # chairs, boxes, a bin, a ball, a pillar, plants
    for _ in range(rng.integers(3, 7)):
        spot = placer.place(inner_x, inner_y, 0.4)
        if spot is None:
            continue
        x, y = spot
        yaw = rng.uniform(0, 2 * np.pi)
        seat = Material(
            "noise",
            0.1,
            _jitter(rng, (0.15, 0.2, 0.45), 0.4),
            (0.1, 0.1, 0.2),
            0.3,
            0.25,
            camera_noise=0.1,
            lidar_noise=0.1,
            seed=_seed(rng),
        )
        seat_id = b.material(seat)
        b.box((x, y, z0 + 0.45), (0.22, 0.22, 0.03), seat_id, yaw=yaw, name="chair seat")
        bx, by = x - 0.2 * math.cos(yaw), y - 0.2 * math.sin(yaw)
        b.box((bx, by, z0 + 0.75), (0.02, 0.22, 0.25), seat_id, yaw=yaw, name="chair back")
        b.cylinder((x, y, z0 + 0.22), 0.03, 0.22, metal_id, name="chair post")
    for _ in range(rng.integers(2, 5)):
        spot = placer.place(inner_x, inner_y, 0.45)
        if spot is None:
            continue
        x, y = spot
        size = rng.uniform(0.2, 0.4)
        b.box(
            (x, y, z0 + size),
            (size, size * rng.uniform(0.7, 1.3), size),
            Material(
                "noise",
                0.3,
                _jitter(rng, (0.6, 0.45, 0.28)),
                (0.5, 0.36, 0.22),
                0.8,
                0.75,
                camera_noise=0.1,
                lidar_noise=0.15,
                seed=_seed(rng),
            ),
            yaw=rng.uniform(0, np.pi),
            name="cardboard box",
        )
    spot = placer.place(inner_x, inner_y, 0.3)
    if spot is not None:
        b.cylinder(
            (spot[0], spot[1], z0 + 0.3),
            0.2,
            0.3,
            Material("stripes", 0.2, (0.1, 0.3, 0.15), (0.8, 0.8, 0.1), 0.3, 0.6, seed=_seed(rng)),
            name="bin",
        )
    spot = placer.place(inner_x, inner_y, 0.3)
    if spot is not None:
        r = rng.uniform(0.15, 0.3)
        b.sphere(
            (spot[0], spot[1], z0 + r),
            r,
            Material(
                "checker", 0.15, (0.85, 0.85, 0.85), (0.8, 0.1, 0.1), 0.8, 0.45, seed=_seed(rng)
            ),
            name="ball",
        )
    spot = placer.place(inner_x, inner_y, 0.4)
    if spot is not None:
        b.cylinder(
            (spot[0], spot[1], zc),
            0.3,
            height / 2,
            Material(
                "noise",
                0.5,
                (0.7, 0.7, 0.68),
                (0.55, 0.55, 0.55),
                0.55,
                0.45,
                camera_noise=0.1,
                lidar_noise=0.2,
                seed=_seed(rng),
            ),
            name="pillar",
        )
    for _ in range(rng.integers(1, 4)):
        spot = placer.place(inner_x, inner_y, 0.45)
        if spot is None:
            continue
        x, y = spot
        b.cylinder(
            (x, y, z0 + 0.2),
            0.18,
            0.2,
            Material("plain", 1.0, (0.45, 0.2, 0.12), (0.45, 0.2, 0.12), 0.4, 0.4, seed=_seed(rng)),
            name="pot",
        )
        leaves = b.material(_leaves(rng))
        for _ in range(rng.integers(3, 6)):
            b.ellipsoid(
                (x + rng.normal(0, 0.12), y + rng.normal(0, 0.12), z0 + rng.uniform(0.55, 1.0)),
                rng.uniform(0.15, 0.3, 3),
                leaves,
                yaw=rng.uniform(0, np.pi),
                name="plant",
            )

    lighting = Lighting(
        sun_irradiance=0.0,
        ambient=0.3,
        point_lights=tuple(lights),
        sky_top=(0.0, 0.0, 0.0),
        sky_horizon=(0.0, 0.0, 0.0),
    )
    return b.build(
        lighting=lighting, modality_gap=config.modality_gap, kind="room", seed=config.seed
    )


def _make_street(config: SceneConfig, rng) -> Scene:
    b = SceneBuilder()
    h = 1.6 if config.sensor_height is None else config.sensor_height
    z0 = -h
    up = (0.0, 0.0, 1.0)
    x_lo, x_hi = -70.0, 110.0
    xm, xr = 0.5 * (x_lo + x_hi), 0.5 * (x_hi - x_lo)
    road_w = rng.uniform(7.0, 10.0)
    # the rig stands in a lane, off the road's centre line
    y_road0 = -road_w / 2 + rng.uniform(-1.2, 1.2)
    y_road1 = y_road0 + road_w
    b.rectangle(
        (xm, 0.5 * (y_road0 + y_road1), z0),
        (1, 0, 0),
        (0, 1, 0),
        (xr, road_w / 2),
        Material(
            "road",
            road_w,
            (0.07, 0.07, 0.075),
            (0.8, 0.8, 0.76),
            0.1,
            3.0,
            camera_noise=0.25,
            lidar_noise=0.35,
            noise_scale=0.6,
            seed=_seed(rng),
            retro=True,
        ),
        name="road",
    )
    # ground beyond everything: grass (dark in the camera, bright in the LiDAR)
    b.rectangle(
        (xm, 0.0, z0 - 0.02),
        (1, 0, 0),
        (0, 1, 0),
        (xr + 40.0, 80.0),
        Material(
            "noise",
            2.0,
            (0.08, 0.18, 0.05),
            (0.12, 0.22, 0.06),
            0.55,
            0.7,
            camera_noise=0.2,
            lidar_noise=0.2,
            noise_scale=0.3,
            seed=_seed(rng),
        ),
        name="grass",
    )
    placer = _Placer(rng, config.clearance)
    pavement = Material(
        "tiles",
        0.4,
        _jitter(rng, (0.45, 0.43, 0.4)),
        (0.25, 0.25, 0.25),
        0.4,
        0.25,
        camera_noise=0.15,
        lidar_noise=0.2,
        noise_scale=0.5,
        seed=_seed(rng),
    )
    kerb = Material("noise", 0.5, (0.6, 0.6, 0.58), (0.5, 0.5, 0.5), 0.5, 0.45, seed=_seed(rng))
    for side in (-1, 1):
        edge = y_road1 if side == 1 else y_road0
        walk_w = rng.uniform(2.5, 4.0)
        yc = edge + side * walk_w / 2
        b.box((xm, yc, z0 + 0.075), (xr, walk_w / 2, 0.075), pavement, name="pavement")
        b.box((xm, edge + side * 0.1, z0 + 0.08), (xr, 0.1, 0.08), kerb, name="kerb")
        front = edge + side * (walk_w + rng.uniform(0.0, 2.0))
        # building facades in a row with alleys between them
        x = x_lo
        while x < x_hi:
            width = rng.uniform(8.0, 25.0)
            if rng.random() < 0.15:
                x += rng.uniform(3.0, 8.0)  # an alley
                continue
            depth = rng.uniform(8.0, 15.0)
            tall = rng.uniform(6.0, 22.0)
            style = rng.integers(3)
            if style == 0:
                facade = Material(
                    "bricks",
                    0.075,
                    _jitter(rng, (0.4, 0.16, 0.1)),
                    (0.55, 0.54, 0.5),
                    0.3,
                    0.45,
                    camera_noise=0.15,
                    lidar_noise=0.15,
                    seed=_seed(rng),
                )
            elif style == 1:
                wall = _jitter(rng, (0.7, 0.65, 0.55), 0.15)
                facade = Material(
                    "windows",
                    rng.uniform(2.5, 3.5),
                    wall,
                    (0.15, 0.2, 0.28),
                    0.55,
                    0.03,
                    camera_noise=0.1,
                    lidar_noise=0.2,
                    noise_scale=0.8,
                    seed=_seed(rng),
                    dropout=0.7,
                )
            else:
                facade = Material(
                    "noise",
                    1.0,
                    _jitter(rng, (0.55, 0.55, 0.55), 0.2),
                    (0.4, 0.4, 0.42),
                    0.4,
                    0.3,
                    camera_noise=0.2,
                    lidar_noise=0.3,
                    noise_scale=0.3,
                    seed=_seed(rng),
                )
            cx = x + width / 2
            cy = front + side * depth / 2
            b.box(
                (cx, cy, z0 + tall / 2), (width / 2, depth / 2, tall / 2), facade, name="building"
            )
            # a shop sign or a poster at street level
            if rng.random() < 0.6:
                sign_w = min(width / 2 - 0.5, rng.uniform(1.5, 4.0))
                b.rectangle(
                    (cx + rng.uniform(-1, 1), front - side * 0.02, z0 + 3.0),
                    (1, 0, 0),
                    up,
                    (sign_w, 0.4),
                    _poster_material(rng),
                    name="shop sign",
                )
            x += width
        # lamp posts and sign poles on the pavement
        pole_y = edge + side * 0.6
        for px in np.arange(x_lo + rng.uniform(0, 15), x_hi, rng.uniform(15.0, 25.0)):
            if not placer.free(px, pole_y, 0.3):
                continue
            placer.take(px, pole_y, 0.3)
            b.cylinder(
                (px, pole_y, z0 + 3.0),
                0.09,
                3.0,
                Material(
                    "stripes",
                    0.5,
                    (0.25, 0.27, 0.25),
                    (0.25, 0.27, 0.25),
                    0.35,
                    0.35,
                    seed=_seed(rng),
                ),
                name="lamp post",
            )
            b.box(
                (px, pole_y - side * 0.5, z0 + 6.0),
                (0.25, 0.6, 0.08),
                Material("plain", 1.0, (0.2, 0.2, 0.2), (0.2, 0.2, 0.2), 0.3, 0.3, seed=_seed(rng)),
                name="lamp",
            )
        for px in np.arange(x_lo + rng.uniform(0, 20), x_hi, rng.uniform(18.0, 30.0)):
            if not placer.free(px, pole_y, 0.5):
                continue
            placer.take(px, pole_y, 0.5)
            b.cylinder(
                (px, pole_y, z0 + 1.3),
                0.035,
                1.3,
                Material(
                    "plain", 1.0, (0.6, 0.6, 0.62), (0.6, 0.6, 0.62), 0.5, 0.5, seed=_seed(rng)
                ),
                name="sign pole",
            )
            facing = rng.choice([-1.0, 1.0])
            b.rectangle(
                (px - facing * 0.05, pole_y, z0 + 2.3),
                (0, facing, 0),
                up,
                (0.3, 0.3),
                _retro_sign(rng),
                name="sign",
            )
        # trees and hedges
        for tx in np.arange(x_lo + rng.uniform(0, 10), x_hi, rng.uniform(9.0, 16.0)):
            ty = edge + side * rng.uniform(1.2, walk_w - 0.5)
            if not placer.free(tx, ty, 1.0):
                continue
            placer.take(tx, ty, 1.0)
            trunk_h = rng.uniform(2.0, 3.0)
            b.cylinder(
                (tx, ty, z0 + trunk_h / 2),
                rng.uniform(0.12, 0.25),
                trunk_h / 2,
                Material(
                    "noise",
                    0.1,
                    (0.25, 0.18, 0.12),
                    (0.15, 0.1, 0.07),
                    0.45,
                    0.35,
                    camera_noise=0.2,
                    lidar_noise=0.2,
                    noise_scale=0.05,
                    seed=_seed(rng),
                ),
                name="trunk",
            )
            leaves = b.material(_leaves(rng))
            for _ in range(rng.integers(3, 7)):
                b.ellipsoid(
                    (
                        tx + rng.normal(0, 0.6),
                        ty + rng.normal(0, 0.6),
                        z0 + trunk_h + rng.uniform(0.3, 1.8),
                    ),
                    rng.uniform(0.8, 1.8, 3),
                    leaves,
                    yaw=rng.uniform(0, np.pi),
                    name="tree crown",
                )
        for _ in range(rng.integers(3, 7)):
            hx = rng.uniform(x_lo, x_hi)
            hy = front - side * 0.6
            if placer.free(hx, hy, 1.0):
                placer.take(hx, hy, 1.0)
                b.ellipsoid(
                    (hx, hy, z0 + 0.5),
                    (rng.uniform(1.0, 3.0), 0.5, 0.7),
                    _leaves(rng),
                    name="hedge",
                )
        # parked cars along the kerb
        for cx in np.arange(x_lo + rng.uniform(0, 10), x_hi, rng.uniform(7.0, 14.0)):
            cy = edge - side * 1.1
            if rng.random() < 0.3 or not placer.free(cx, cy, 2.4):
                continue
            placer.take(cx, cy, 2.4)
            paint = tuple(float(v) for v in rng.uniform(0.02, 0.7, 3))
            body = b.material(
                Material(
                    "noise",
                    2.0,
                    paint,
                    _jitter(rng, paint, 0.1),
                    0.3,
                    0.3,
                    camera_noise=0.05,
                    lidar_noise=0.05,
                    seed=_seed(rng),
                )
            )
            b.box((cx, cy, z0 + 0.65), (2.1, 0.88, 0.35), body, name="car body")
            b.box(
                (cx - 0.2, cy, z0 + 1.25),
                (1.1, 0.78, 0.27),
                Material(
                    "windows",
                    0.7,
                    paint,
                    (0.05, 0.07, 0.1),
                    0.3,
                    0.03,
                    camera_noise=0.05,
                    seed=_seed(rng),
                    dropout=0.6,
                ),
                name="car cabin",
            )
            for wx in (-1.35, 1.35):
                b.cylinder(
                    (cx + wx, cy, z0 + 0.32),
                    0.32,
                    0.93,
                    Material(
                        "plain",
                        1.0,
                        (0.03, 0.03, 0.03),
                        (0.03, 0.03, 0.03),
                        0.05,
                        0.05,
                        seed=_seed(rng),
                    ),
                    axis=(0, 1, 0),
                    name="wheels",
                )
            for end in (-1, 1):
                b.rectangle(
                    (cx + end * 2.11, cy, z0 + 0.6),
                    (0, end, 0),
                    up,
                    (0.26, 0.06),
                    Material(
                        "text",
                        0.1,
                        (0.9, 0.9, 0.85),
                        (0.05, 0.05, 0.05),
                        3.0,
                        0.6,
                        seed=_seed(rng),
                        retro=True,
                    ),
                    name="number plate",
                )
        # bollards with balls on top
        for _ in range(rng.integers(2, 6)):
            bx = rng.uniform(-20.0, 40.0)
            by = edge + side * 0.35
            if placer.free(bx, by, 0.4):
                placer.take(bx, by, 0.4)
                b.cylinder(
                    (bx, by, z0 + 0.45),
                    0.1,
                    0.45,
                    Material(
                        "stripes", 0.3, (0.8, 0.8, 0.8), (0.1, 0.1, 0.1), 0.6, 0.1, seed=_seed(rng)
                    ),
                    axis=(0, 0, 1),
                    name="bollard",
                )
                b.sphere(
                    (bx, by, z0 + 1.0),
                    0.12,
                    Material(
                        "plain", 1.0, (0.7, 0.6, 0.1), (0.7, 0.6, 0.1), 0.5, 0.5, seed=_seed(rng)
                    ),
                    name="ball",
                )

    elevation = rng.uniform(np.radians(30), np.radians(60))
    azimuth = rng.uniform(0, 2 * np.pi)
    sun = (
        math.cos(elevation) * math.cos(azimuth),
        math.cos(elevation) * math.sin(azimuth),
        math.sin(elevation),
    )
    lighting = Lighting(sun_direction=sun, sun_irradiance=1.0, ambient=0.45)
    return b.build(
        lighting=lighting, modality_gap=config.modality_gap, kind="street", seed=config.seed
    )
