"""The ``"room"`` scene: an office-like room around the rig.

Walls of plaster, bricks, panels or concrete with skirting boards; a tiled or wooden floor; a
ceiling with light panels (two of them cast shadows); posters, a whiteboard, a door, windows and
an exit sign on the walls; a rug, tables with a box on top, cabinets and bookshelves along the
walls, chairs, cardboard boxes, a bin, a ball, a pillar and potted plants on the floor.

:func:`make_room` draws everything from one generator, step by step in the order of the functions
below; the order of the draws is what a seed means, so a step must not draw more or earlier.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nbcalib.synthetic.builder import (
    Placer,
    SceneBuilder,
    foliage_material,
    jitter,
    plain_material,
    poster_material,
    retro_sign_material,
    seeded_material,
)
from nbcalib.synthetic.scene import Lighting, Scene, SceneConfig
from nbcalib.synthetic.texture import Material

__all__ = ["make_room"]

UP = (0.0, 0.0, 1.0)


@dataclass(frozen=True)
class _Room:
    """Extent of the room in the world frame, metres (the rig at the origin, off-centre)."""

    size_x: float
    size_y: float
    height: float  # floor to ceiling
    x0: float
    x1: float
    y0: float
    y1: float
    z0: float  # floor
    z1: float  # ceiling

    @property
    def zc(self) -> float:
        """Height of the walls' centre."""
        return 0.5 * (self.z0 + self.z1)

    @property
    def centre(self) -> tuple[float, float]:
        """Centre of the floor plan."""
        return (self.x0 + self.x1) / 2, (self.y0 + self.y1) / 2

    @property
    def inner_x(self) -> tuple[float, float]:
        """Range of x where objects stand free of the walls."""
        return (self.x0 + 0.8, self.x1 - 0.8)

    @property
    def inner_y(self) -> tuple[float, float]:
        """Range of y where objects stand free of the walls."""
        return (self.y0 + 0.8, self.y1 - 0.8)


def make_room(config: SceneConfig, rng) -> Scene:
    """Generate a room from ``rng`` (module docstring); ``config`` as in ``make_scene``."""
    b = SceneBuilder()
    room = _extent(config, rng)
    _floor_and_ceiling(b, rng, room)
    lights = _ceiling_lights(b, rng, room)
    for wall in _walls(room):
        _wall(b, rng, room, wall)
    _furnish(b, rng, room, Placer(rng, config.clearance))
    lighting = Lighting(
        sun_irradiance=0.0,
        ambient=0.3,
        point_lights=tuple(lights),
        sky_top=(0.0, 0.0, 0.0),
        sky_horizon=(0.0, 0.0, 0.0),
    )
    return b.build(
        lighting=lighting,
        modality_gap=config.modality_gap,
        without=config.without,
        kind="room",
        seed=config.seed,
    )


def _extent(config: SceneConfig, rng) -> _Room:
    """Size and height of the room, and where the rig stands in it."""
    h = 1.2 if config.sensor_height is None else config.sensor_height
    size_x, size_y = rng.uniform(8.0, 12.0), rng.uniform(6.0, 9.0)
    height = rng.uniform(2.8, 3.5)
    # the rig is off-centre, at least 2.5 m from every wall
    cx = rng.uniform(-(size_x / 2 - 2.5), size_x / 2 - 2.5)
    cy = rng.uniform(-(size_y / 2 - 2.5), size_y / 2 - 2.5)
    x0, x1, y0, y1 = cx - size_x / 2, cx + size_x / 2, cy - size_y / 2, cy + size_y / 2
    return _Room(size_x, size_y, height, x0, x1, y0, y1, -h, height - h)


def _floor_and_ceiling(b: SceneBuilder, rng, room: _Room) -> None:
    if rng.random() < 0.5:
        size = rng.uniform(0.4, 0.6)
        tile = jitter(rng, (0.55, 0.52, 0.47))
        floor = seeded_material(
            rng, "tiles", size, tile, (0.3, 0.3, 0.3), (0.45, 0.25), (0.1, 0.2, 0.25)
        )
    else:
        wood = jitter(rng, (0.45, 0.3, 0.17))
        floor = seeded_material(
            rng, "planks", 0.18, wood, (0.15, 0.1, 0.06), (0.45, 0.2), (0.1, 0.15, 0.3)
        )
    half = (room.size_x / 2, room.size_y / 2)
    cx, cy = room.centre
    b.rectangle((cx, cy, room.z0), (1, 0, 0), (0, 1, 0), half, floor, name="floor")
    ceiling = seeded_material(
        rng, "tiles", 0.6, (0.8, 0.8, 0.78), (0.55, 0.55, 0.55), (0.7, 0.5), (0.05, 0.1, 0.5)
    )
    b.rectangle((cx, cy, room.z1), (1, 0, 0), (0, 1, 0), half, ceiling, name="ceiling")


def _ceiling_lights(b: SceneBuilder, rng, room: _Room) -> list[tuple[float, float, float, float]]:
    """Light panels in a grid on the ceiling; returns the point lights ``(x, y, z, power)``."""
    panel = seeded_material(
        rng, "plain", 1.0, (1.0, 1.0, 0.97), (1.0, 1.0, 0.97), (0.7, 0.7), (0.0, 0.05, 0.5)
    )
    for gx in np.linspace(room.x0, room.x1, 5)[1:-1]:
        for gy in np.linspace(room.y0, room.y1, 4)[1:-1]:
            b.rectangle(
                (gx, gy, room.z1 - 0.01),
                (1, 0, 0),
                (0, 1, 0),
                (0.6, 0.3),
                panel,
                name="light panel",
            )
    # two lights cast the shadows (each costs the renderer one shadow ray per pixel)
    y_mid = float(0.5 * (room.y0 + room.y1))
    return [
        (float(gx), y_mid, float(room.z1 - 0.3), 4.0)
        for gx in np.linspace(room.x0, room.x1, 4)[1:-1]
    ]


@dataclass(frozen=True)
class _Wall:
    """One wall: centre ``(x, y)``, unit direction along it, inward normal, half length."""

    centre: tuple[float, float]
    along: tuple[float, float]
    normal: tuple[float, float]
    half_len: float


def _walls(room: _Room) -> list[_Wall]:
    cx, cy = room.centre
    return [
        _Wall((room.x1, cy), (0.0, 1.0), (-1.0, 0.0), room.size_y / 2),
        _Wall((room.x0, cy), (0.0, -1.0), (1.0, 0.0), room.size_y / 2),
        _Wall((cx, room.y1), (-1.0, 0.0), (0.0, -1.0), room.size_x / 2),
        _Wall((cx, room.y0), (1.0, 0.0), (0.0, 1.0), room.size_x / 2),
    ]


def _wall_material(rng) -> Material:
    """Painted plaster, bricks, wooden panels or concrete."""
    choice = rng.integers(0, 4)
    if choice == 0:  # painted plaster: stains for the camera, a different blotch for the LiDAR
        paint = jitter(
            rng, [(0.75, 0.72, 0.66), (0.62, 0.68, 0.72), (0.78, 0.74, 0.55)][rng.integers(3)]
        )
        blotch = jitter(rng, paint, 0.15)
        return seeded_material(rng, "noise", 1.5, paint, blotch, (0.55, 0.6), (0.12, 0.2, 0.4))
    if choice == 1:  # bricks
        brick = jitter(rng, (0.42, 0.17, 0.1))
        mortar = (0.55, 0.54, 0.5)
        return seeded_material(rng, "bricks", 0.075, brick, mortar, (0.35, 0.45), (0.15, 0.15, 0.3))
    if choice == 2:  # wooden panels
        wood = jitter(rng, (0.5, 0.34, 0.2))
        return seeded_material(
            rng, "planks", 0.3, wood, (0.2, 0.13, 0.08), (0.5, 0.2), (0.1, 0.1, 0.5)
        )
    concrete = ((0.5, 0.5, 0.48), (0.36, 0.36, 0.35))
    return seeded_material(rng, "noise", 0.8, *concrete, (0.4, 0.3), (0.15, 0.25, 0.2))


def _wall(b: SceneBuilder, rng, room: _Room, wall: _Wall) -> None:
    """A wall, its skirting board, and posters, boards, a door, windows or signs on it."""
    (wx, wy), (ax, ay), (nx, ny) = wall.centre, wall.along, wall.normal
    half_len = wall.half_len
    along = (ax, ay, 0.0)
    b.rectangle(
        (wx, wy, room.zc), along, UP, (half_len, room.height / 2), _wall_material(rng), name="wall"
    )
    b.box(
        (wx + 0.01 * nx, wy + 0.01 * ny, room.z0 + 0.05),
        (half_len if ax else 0.01, 0.01 if ax else half_len, 0.05),
        plain_material(rng, (0.15, 0.14, 0.13), 0.2),
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
        w2, h2, zm, material = _wall_item(rng, kind, width)
        b.rectangle(
            (centre_xy[0], centre_xy[1], room.z0 + min(zm, room.height - h2 - 0.05)),
            along,
            UP,
            (w2, h2),
            material,
            name=kind,
        )


def _wall_item(rng, kind, width) -> tuple[float, float, float, Material]:
    """Half width, half height, height of the centre above the floor, material of a wall item."""
    if kind == "poster":
        w2, h2, zm = width / 2, rng.uniform(0.3, 0.6), rng.uniform(1.4, 1.9)
        return w2, h2, zm, poster_material(rng)
    if kind == "board":
        white, ink = (0.92, 0.92, 0.92), (0.1, 0.15, 0.5)
        return (
            width / 2,
            0.55,
            1.45,
            seeded_material(rng, "text", 0.09, white, ink, (0.8, 0.7), (0.05, 0.05, 0.5)),
        )
    if kind == "door":
        wood = jitter(rng, (0.35, 0.22, 0.12))
        return (
            0.45,
            1.02,
            1.02,
            seeded_material(
                rng, "planks", 0.15, wood, (0.2, 0.12, 0.07), (0.45, 0.25), (0.1, 0.1, 0.5)
            ),
        )
    if kind == "window":  # glass: weak and often lost for the LiDAR
        glass = ((0.85, 0.9, 0.95), (0.8, 0.85, 0.92))
        return (
            width / 2,
            0.6,
            1.6,
            seeded_material(
                rng, "stripes", width / 2, *glass, (0.03, 0.03), (0.15, 0.0, 0.3), dropout=0.7
            ),
        )
    return 0.175, 0.09, 2.3, retro_sign_material(rng, (0.05, 0.55, 0.15))  # an exit sign


def _furnish(b: SceneBuilder, rng, room: _Room, placer: Placer) -> None:
    """Everything on the floor, in a fixed order (each step takes its spots from ``placer``)."""
    metal = b.material(
        seeded_material(
            rng, "noise", 0.3, (0.35, 0.35, 0.37), (0.5, 0.5, 0.52), (0.4, 0.45), (0.05, 0.1, 0.5)
        )
    )
    _rug(b, rng, room, placer)
    _tables(b, rng, room, placer, metal)
    _cabinets_and_shelves(b, rng, room, placer)
    _chairs(b, rng, room, placer, metal)
    _cardboard_boxes(b, rng, room, placer)
    _bin_ball_and_pillar(b, rng, room, placer)
    _potted_plants(b, rng, room, placer)


def _wood(rng) -> Material:
    return seeded_material(
        rng, "planks", 0.12, jitter(rng, (0.5, 0.35, 0.2)), (0.3, 0.2, 0.12), (0.5, 0.35)
    )


def _rug(b: SceneBuilder, rng, room: _Room, placer: Placer) -> None:
    """A rug on the floor (a pattern for both sensors, softer for the LiDAR)."""
    rug = placer.place(room.inner_x, room.inner_y, 0.8, tries=20)
    if rug is None:
        return
    turn = rng.uniform(0, np.pi)
    half = rng.uniform(0.6, 1.2, 2)
    pattern = str(rng.choice(["stripes", "checker", "noise"]))
    scale = rng.uniform(0.15, 0.4)
    colours = jitter(rng, (0.6, 0.15, 0.1), 0.5), jitter(rng, (0.8, 0.75, 0.6), 0.2)
    b.rectangle(
        (rug[0], rug[1], room.z0 + 0.005),
        (math.cos(turn), math.sin(turn), 0.0),
        (-math.sin(turn), math.cos(turn), 0.0),
        half,
        seeded_material(rng, pattern, scale, *colours, (0.55, 0.7), (0.15, 0.15, 0.1)),
        name="rug",
    )


def _tables(b: SceneBuilder, rng, room: _Room, placer: Placer, metal: int) -> None:
    """Tables with four legs and a box on top."""
    z0 = room.z0
    for _ in range(rng.integers(2, 5)):
        spot = placer.place(room.inner_x, room.inner_y, 1.1)
        if spot is None:
            continue
        x, y = spot
        yaw = rng.uniform(0, np.pi)
        la, lb = rng.uniform(0.6, 0.9), rng.uniform(0.35, 0.5)
        b.box((x, y, z0 + 0.74), (la, lb, 0.02), _wood(rng), yaw=yaw, name="table top")
        c, s = math.cos(yaw), math.sin(yaw)
        for sa in (-1, 1):
            for sb in (-1, 1):
                lx, ly = sa * (la - 0.06), sb * (lb - 0.06)
                b.cylinder(
                    (x + c * lx - s * ly, y + s * lx + c * ly, z0 + 0.36),
                    0.025,
                    0.36,
                    metal,
                    name="table leg",
                )
        cardboard = jitter(rng, (0.55, 0.4, 0.25))
        b.box(
            (x, y, z0 + 0.76 + 0.08),
            (0.15, 0.1, 0.08),
            seeded_material(rng, "noise", 0.2, cardboard, (0.4, 0.3, 0.2), (0.75, 0.7)),
            yaw=rng.uniform(0, np.pi),
            name="box",
        )


def _cabinets_and_shelves(b: SceneBuilder, rng, room: _Room, placer: Placer) -> None:
    """Cabinets and bookshelves against the walls."""
    x0, x1, y0, y1, z0 = room.x0, room.x1, room.y0, room.y1, room.z0
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
        centre, size = (x, y, z0 + tall / 2), (half[0], half[1], tall / 2)
        if rng.random() < 0.5:
            b.box(centre, size, _wood(rng), name="cabinet")
            continue
        # a shelf of books: colourful for the camera, much the same for the LiDAR
        spines = jitter(rng, (0.7, 0.2, 0.1), 0.6), jitter(rng, (0.1, 0.3, 0.6), 0.6)
        books = seeded_material(rng, "stripes", 0.04, *spines, (0.5, 0.45), (0.3, 0.1, 0.03))
        b.box(centre, size, books, name="bookshelf")


def _chairs(b: SceneBuilder, rng, room: _Room, placer: Placer, metal: int) -> None:
    """Chairs: a seat and a back on a post."""
    z0 = room.z0
    for _ in range(rng.integers(3, 7)):
        spot = placer.place(room.inner_x, room.inner_y, 0.4)
        if spot is None:
            continue
        x, y = spot
        yaw = rng.uniform(0, 2 * np.pi)
        fabric = jitter(rng, (0.15, 0.2, 0.45), 0.4)
        seat = b.material(seeded_material(rng, "noise", 0.1, fabric, (0.1, 0.1, 0.2), (0.3, 0.25)))
        b.box((x, y, z0 + 0.45), (0.22, 0.22, 0.03), seat, yaw=yaw, name="chair seat")
        bx, by = x - 0.2 * math.cos(yaw), y - 0.2 * math.sin(yaw)
        b.box((bx, by, z0 + 0.75), (0.02, 0.22, 0.25), seat, yaw=yaw, name="chair back")
        b.cylinder((x, y, z0 + 0.22), 0.03, 0.22, metal, name="chair post")


def _cardboard_boxes(b: SceneBuilder, rng, room: _Room, placer: Placer) -> None:
    for _ in range(rng.integers(2, 5)):
        spot = placer.place(room.inner_x, room.inner_y, 0.45)
        if spot is None:
            continue
        x, y = spot
        size = rng.uniform(0.2, 0.4)
        half = (size, size * rng.uniform(0.7, 1.3), size)
        cardboard = jitter(rng, (0.6, 0.45, 0.28))
        b.box(
            (x, y, room.z0 + size),
            half,
            seeded_material(
                rng, "noise", 0.3, cardboard, (0.5, 0.36, 0.22), (0.8, 0.75), (0.1, 0.15, 0.5)
            ),
            yaw=rng.uniform(0, np.pi),
            name="cardboard box",
        )


def _bin_ball_and_pillar(b: SceneBuilder, rng, room: _Room, placer: Placer) -> None:
    z0 = room.z0
    spot = placer.place(room.inner_x, room.inner_y, 0.3)
    if spot is not None:
        stripes = seeded_material(
            rng, "stripes", 0.2, (0.1, 0.3, 0.15), (0.8, 0.8, 0.1), (0.3, 0.6)
        )
        b.cylinder((spot[0], spot[1], z0 + 0.3), 0.2, 0.3, stripes, name="bin")
    spot = placer.place(room.inner_x, room.inner_y, 0.3)
    if spot is not None:
        r = rng.uniform(0.15, 0.3)
        checks = seeded_material(rng, "checker", 0.15, (0.85,) * 3, (0.8, 0.1, 0.1), (0.8, 0.45))
        b.sphere((spot[0], spot[1], z0 + r), r, checks, name="ball")
    spot = placer.place(room.inner_x, room.inner_y, 0.4)
    if spot is not None:
        concrete = seeded_material(
            rng, "noise", 0.5, (0.7, 0.7, 0.68), (0.55,) * 3, (0.55, 0.45), (0.1, 0.2, 0.5)
        )
        b.cylinder((spot[0], spot[1], room.zc), 0.3, room.height / 2, concrete, name="pillar")


def _potted_plants(b: SceneBuilder, rng, room: _Room, placer: Placer) -> None:
    z0 = room.z0
    for _ in range(rng.integers(1, 4)):
        spot = placer.place(room.inner_x, room.inner_y, 0.45)
        if spot is None:
            continue
        x, y = spot
        pot = plain_material(rng, (0.45, 0.2, 0.12), 0.4)
        b.cylinder((x, y, z0 + 0.2), 0.18, 0.2, pot, name="pot")
        leaves = b.material(foliage_material(rng))
        for _ in range(rng.integers(3, 6)):
            b.ellipsoid(
                (x + rng.normal(0, 0.12), y + rng.normal(0, 0.12), z0 + rng.uniform(0.55, 1.0)),
                rng.uniform(0.15, 0.3, 3),
                leaves,
                yaw=rng.uniform(0, np.pi),
                name="plant",
            )
