"""Building scenes: :class:`SceneBuilder`, and the helpers the procedural scenes share.

:class:`SceneBuilder` collects primitives (rectangles, boxes, cylinders, ellipsoids) and
materials and packs them into a :class:`~nbcalib.synthetic.scene.Scene` with its hierarchy. The
generators of :mod:`nbcalib.synthetic.scenes` add :class:`Placer` (free spots on the floor) and
the seeded material helpers below.

Every helper that takes ``rng`` draws from it in a fixed order, which is part of what a seed
means: a seed gives the same scene only while the draws stay in the same order. A material's own
seed is drawn last, after its colours.
"""

from __future__ import annotations

import math

import numpy as np

from nbcalib.kernels import raycast as _rc
from nbcalib.kernels.synthetic_texture import MAT_SIZE
from nbcalib.synthetic.bvh import build_bvh
from nbcalib.synthetic.effects import TEXTURE_EFFECTS, check_effects
from nbcalib.synthetic.scene import Lighting, Scene
from nbcalib.synthetic.texture import Material

__all__ = [
    "Placer",
    "SceneBuilder",
    "draw_seed",
    "foliage_material",
    "jitter",
    "plain_material",
    "poster_material",
    "retro_sign_material",
    "seeded_material",
]


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

    def build(self, *, lighting=None, modality_gap=1.0, without=(), kind="custom", seed=0) -> Scene:
        """Pack everything into a :class:`Scene` (and build its hierarchy).

        ``without``: texture differences switched off, as
        :attr:`nbcalib.synthetic.scene.SceneConfig.without`.
        """
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
            without=check_effects(without, TEXTURE_EFFECTS),
            kind=kind,
            seed=int(seed),
        )


class Placer:
    """Rejection sampling of object footprints (circles) that keep clear of each other.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the candidate spots.
    clearance : float
        Radius kept free around the origin (the rig), metres.
    """

    def __init__(self, rng, clearance):
        self.rng = rng
        self.taken: list[tuple[float, float, float]] = [(0.0, 0.0, clearance)]

    def free(self, x, y, r) -> bool:
        """Whether a circle of radius ``r`` at ``(x, y)`` keeps clear of everything taken."""
        return all(math.hypot(x - a, y - b) >= r + c for a, b, c in self.taken)

    def take(self, x, y, r) -> None:
        """Mark a circle of radius ``r`` at ``(x, y)`` as taken."""
        self.taken.append((x, y, r))

    def place(self, x_range, y_range, r, *, tries=40):
        """Take a free spot drawn uniformly in the ranges: ``(x, y)``, or None after ``tries``."""
        for _ in range(tries):
            x = self.rng.uniform(*x_range)
            y = self.rng.uniform(*y_range)
            if self.free(x, y, r):
                self.take(x, y, r)
                return x, y
        return None


def jitter(rng, color, amount=0.08) -> tuple[float, float, float]:
    """``color`` with each channel scaled by a factor drawn in ``1 +- amount``, clipped to 0..1."""
    c = np.asarray(color) * (1.0 + rng.uniform(-amount, amount, 3))
    return tuple(float(v) for v in np.clip(c, 0.0, 1.0))


def draw_seed(rng) -> int:
    """A material seed drawn from ``rng``."""
    return int(rng.integers(0, 1_000_000))


def seeded_material(
    rng, pattern, scale, color_a, color_b, reflectivity, noise=(0.1, 0.1, 0.5), **options
) -> Material:
    """A :class:`Material` whose seed is the next draw of ``rng``.

    Parameters
    ----------
    rng : numpy.random.Generator
        Gives the seed (drawn after the caller has evaluated the other arguments).
    pattern, scale, color_a, color_b
        As in :class:`Material`.
    reflectivity : tuple of 2 floats
        ``(reflectivity_a, reflectivity_b)``.
    noise : tuple of 3 floats
        ``(camera_noise, lidar_noise, noise_scale)``; the default is :class:`Material`'s.
    **options
        ``dropout``, ``retro``.
    """
    camera_noise, lidar_noise, noise_scale = noise
    return Material(
        pattern,
        scale,
        color_a,
        color_b,
        reflectivity[0],
        reflectivity[1],
        camera_noise=camera_noise,
        lidar_noise=lidar_noise,
        noise_scale=noise_scale,
        seed=draw_seed(rng),
        **options,
    )


def plain_material(rng, color, reflectivity) -> Material:
    """One colour and one reflectivity, the default single-modality noise; seeded by ``rng``."""
    return Material("plain", 1.0, color, color, reflectivity, reflectivity, seed=draw_seed(rng))


def poster_material(rng) -> Material:
    """A poster, print or picture: text, a checkerboard, colour blotches or IR-only print."""
    kind = rng.integers(0, 4)
    paper = jitter(rng, (0.85, 0.84, 0.8), 0.05)
    if kind == 0:  # printed text: ink nearly transparent to the LiDAR's infrared
        ink = jitter(rng, (0.05, 0.05, 0.1), 0.3)
        return seeded_material(rng, "text", 0.06, paper, ink, (0.8, 0.65), (0.02, 0.05, 0.5))
    if kind == 1:  # a checkerboard poster (bright in both)
        black = (0.04, 0.04, 0.04)
        return seeded_material(rng, "checker", 0.08, paper, black, (0.85, 0.1), (0.02, 0.05, 0.5))
    if kind == 2:  # a picture: colourful blotches the LiDAR hardly sees
        colour = tuple(float(v) for v in rng.uniform(0.05, 0.8, 3))
        blotches = jitter(rng, (0.7, 0.3, 0.1), 0.5)
        return seeded_material(rng, "noise", 0.12, colour, blotches, (0.6, 0.55), (0.3, 0.05, 0.05))
    # IR-absorbing print: invisible to the camera, written in the LiDAR image
    return seeded_material(rng, "text", 0.1, paper, paper, (0.8, 0.1), (0.03, 0.05, 0.5))


def foliage_material(rng) -> Material:
    """Leaves: dark for the camera, bright for the LiDAR (chlorophyll reflects infrared)."""
    dark = jitter(rng, (0.04, 0.12, 0.03), 0.2)
    lit = jitter(rng, (0.1, 0.28, 0.06), 0.2)
    return seeded_material(rng, "leaves", 0.25, dark, lit, (0.65, 0.85), (0.2, 0.2, 0.1))


def retro_sign_material(rng, colour=None) -> Material:
    """A retro-reflective traffic sign (red, blue or green unless ``colour`` is given)."""
    colour = colour or [(0.8, 0.05, 0.03), (0.05, 0.2, 0.7), (0.05, 0.5, 0.1)][rng.integers(3)]
    face = jitter(rng, colour, 0.1)
    white = (0.9, 0.9, 0.88)
    return seeded_material(rng, "sign", 0.6, face, white, (4.0, 0.9), (0.03, 0.05, 0.5), retro=True)
