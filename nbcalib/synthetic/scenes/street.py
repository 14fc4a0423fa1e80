"""The ``"street"`` scene: a straight street along x, the rig standing in a lane.

Asphalt with lane markings and grass beyond everything; on each side a kerb and a pavement,
building facades (bricks, rendered walls with windows, concrete) with alleys between them and shop
signs at street level, lamp posts, sign poles with retro-reflective signs, trees and hedges,
parked cars with retro-reflective number plates, and bollards.

:func:`make_street` draws everything from one generator, step by step in the order of the
functions below; the order of the draws is what a seed means, so a step must not draw more or
earlier.
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

__all__ = ["make_street"]

UP = (0.0, 0.0, 1.0)
#: the street runs from X_LO to X_HI metres along the world x axis
X_LO, X_HI = -70.0, 110.0
XM, XR = 0.5 * (X_LO + X_HI), 0.5 * (X_HI - X_LO)


@dataclass(frozen=True)
class _Side:
    """One side of the street: ``sign`` +1 (left, +y) or -1, its kerb line and its pavement."""

    sign: int
    edge: float  # y of the kerb line (the road's edge)
    walk_w: float  # width of the pavement
    front: float  # y of the building fronts
    z0: float  # road level

    @property
    def pole_y(self) -> float:
        """Where the lamp posts and sign poles stand across the street (y)."""
        return self.edge + self.sign * 0.6


def make_street(config: SceneConfig, rng) -> Scene:
    """Generate a street from ``rng`` (module docstring); ``config`` as in ``make_scene``."""
    b = SceneBuilder()
    h = 1.6 if config.sensor_height is None else config.sensor_height
    z0 = -h
    y_road0, y_road1 = _road_and_grass(b, rng, z0)
    placer = Placer(rng, config.clearance)
    pavement = seeded_material(
        rng,
        "tiles",
        0.4,
        jitter(rng, (0.45, 0.43, 0.4)),
        (0.25, 0.25, 0.25),
        (0.4, 0.25),
        (0.15, 0.2, 0.5),
    )
    kerb = seeded_material(rng, "noise", 0.5, (0.6, 0.6, 0.58), (0.5, 0.5, 0.5), (0.5, 0.45))
    for sign in (-1, 1):
        side = _pavement(b, rng, sign, y_road1 if sign == 1 else y_road0, z0, pavement, kerb)
        _facades(b, rng, side)
        _lamp_posts(b, rng, side, placer)
        _sign_poles(b, rng, side, placer)
        _trees(b, rng, side, placer)
        _hedges(b, rng, side, placer)
        _parked_cars(b, rng, side, placer)
        _bollards(b, rng, side, placer)
    return b.build(
        lighting=_sunlight(rng),
        modality_gap=config.modality_gap,
        without=config.without,
        kind="street",
        seed=config.seed,
    )


def _road_and_grass(b: SceneBuilder, rng, z0: float) -> tuple[float, float]:
    """The road (lane markings for both sensors) and the ground; returns the road's edges (y)."""
    road_w = rng.uniform(7.0, 10.0)
    # the rig stands in a lane, off the road's centre line
    y_road0 = -road_w / 2 + rng.uniform(-1.2, 1.2)
    y_road1 = y_road0 + road_w
    asphalt, paint = (0.07, 0.07, 0.075), (0.8, 0.8, 0.76)
    b.rectangle(
        (XM, 0.5 * (y_road0 + y_road1), z0),
        (1, 0, 0),
        (0, 1, 0),
        (XR, road_w / 2),
        seeded_material(
            rng, "road", road_w, asphalt, paint, (0.1, 3.0), (0.25, 0.35, 0.6), retro=True
        ),
        name="road",
    )
    # ground beyond everything: grass (dark in the camera, bright in the LiDAR)
    grass = seeded_material(
        rng, "noise", 2.0, (0.08, 0.18, 0.05), (0.12, 0.22, 0.06), (0.55, 0.7), (0.2, 0.2, 0.3)
    )
    b.rectangle((XM, 0.0, z0 - 0.02), (1, 0, 0), (0, 1, 0), (XR + 40.0, 80.0), grass, name="grass")
    return y_road0, y_road1


def _pavement(b: SceneBuilder, rng, sign, edge, z0, pavement, kerb) -> _Side:
    """The pavement and the kerb of one side, and where its buildings start."""
    walk_w = rng.uniform(2.5, 4.0)
    yc = edge + sign * walk_w / 2
    b.box((XM, yc, z0 + 0.075), (XR, walk_w / 2, 0.075), pavement, name="pavement")
    b.box((XM, edge + sign * 0.1, z0 + 0.08), (XR, 0.1, 0.08), kerb, name="kerb")
    front = edge + sign * (walk_w + rng.uniform(0.0, 2.0))
    return _Side(sign, edge, walk_w, front, z0)


def _facade_material(rng) -> Material:
    """Bricks, a rendered wall with windows (glass: lost LiDAR returns), or concrete."""
    style = rng.integers(3)
    if style == 0:
        brick = jitter(rng, (0.4, 0.16, 0.1))
        mortar = (0.55, 0.54, 0.5)
        return seeded_material(rng, "bricks", 0.075, brick, mortar, (0.3, 0.45), (0.15, 0.15, 0.5))
    if style == 1:
        wall = jitter(rng, (0.7, 0.65, 0.55), 0.15)
        pitch = rng.uniform(2.5, 3.5)
        glass = (0.15, 0.2, 0.28)
        return seeded_material(
            rng, "windows", pitch, wall, glass, (0.55, 0.03), (0.1, 0.2, 0.8), dropout=0.7
        )
    concrete = jitter(rng, (0.55, 0.55, 0.55), 0.2)
    return seeded_material(
        rng, "noise", 1.0, concrete, (0.4, 0.4, 0.42), (0.4, 0.3), (0.2, 0.3, 0.3)
    )


def _facades(b: SceneBuilder, rng, side: _Side) -> None:
    """Buildings in a row with alleys between them, some with a shop sign or a poster."""
    z0 = side.z0
    x = X_LO
    while x < X_HI:
        width = rng.uniform(8.0, 25.0)
        if rng.random() < 0.15:
            x += rng.uniform(3.0, 8.0)  # an alley
            continue
        depth = rng.uniform(8.0, 15.0)
        tall = rng.uniform(6.0, 22.0)
        facade = _facade_material(rng)
        cx = x + width / 2
        cy = side.front + side.sign * depth / 2
        b.box((cx, cy, z0 + tall / 2), (width / 2, depth / 2, tall / 2), facade, name="building")
        # a shop sign or a poster at street level
        if rng.random() < 0.6:
            sign_w = min(width / 2 - 0.5, rng.uniform(1.5, 4.0))
            b.rectangle(
                (cx + rng.uniform(-1, 1), side.front - side.sign * 0.02, z0 + 3.0),
                (1, 0, 0),
                UP,
                (sign_w, 0.4),
                poster_material(rng),
                name="shop sign",
            )
        x += width


def _lamp_posts(b: SceneBuilder, rng, side: _Side, placer: Placer) -> None:
    z0, pole_y = side.z0, side.pole_y
    for px in np.arange(X_LO + rng.uniform(0, 15), X_HI, rng.uniform(15.0, 25.0)):
        if not placer.free(px, pole_y, 0.3):
            continue
        placer.take(px, pole_y, 0.3)
        grey = (0.25, 0.27, 0.25)
        post = seeded_material(rng, "stripes", 0.5, grey, grey, (0.35, 0.35))
        b.cylinder((px, pole_y, z0 + 3.0), 0.09, 3.0, post, name="lamp post")
        lamp = plain_material(rng, (0.2, 0.2, 0.2), 0.3)
        b.box((px, pole_y - side.sign * 0.5, z0 + 6.0), (0.25, 0.6, 0.08), lamp, name="lamp")


def _sign_poles(b: SceneBuilder, rng, side: _Side, placer: Placer) -> None:
    z0, pole_y = side.z0, side.pole_y
    for px in np.arange(X_LO + rng.uniform(0, 20), X_HI, rng.uniform(18.0, 30.0)):
        if not placer.free(px, pole_y, 0.5):
            continue
        placer.take(px, pole_y, 0.5)
        pole = plain_material(rng, (0.6, 0.6, 0.62), 0.5)
        b.cylinder((px, pole_y, z0 + 1.3), 0.035, 1.3, pole, name="sign pole")
        facing = rng.choice([-1.0, 1.0])
        b.rectangle(
            (px - facing * 0.05, pole_y, z0 + 2.3),
            (0, facing, 0),
            UP,
            (0.3, 0.3),
            retro_sign_material(rng),
            name="sign",
        )


def _trees(b: SceneBuilder, rng, side: _Side, placer: Placer) -> None:
    """Trees on the pavement: a trunk and a few ellipsoid crowns."""
    z0 = side.z0
    for tx in np.arange(X_LO + rng.uniform(0, 10), X_HI, rng.uniform(9.0, 16.0)):
        ty = side.edge + side.sign * rng.uniform(1.2, side.walk_w - 0.5)
        if not placer.free(tx, ty, 1.0):
            continue
        placer.take(tx, ty, 1.0)
        trunk_h = rng.uniform(2.0, 3.0)
        radius = rng.uniform(0.12, 0.25)
        bark = seeded_material(
            rng, "noise", 0.1, (0.25, 0.18, 0.12), (0.15, 0.1, 0.07), (0.45, 0.35), (0.2, 0.2, 0.05)
        )
        b.cylinder((tx, ty, z0 + trunk_h / 2), radius, trunk_h / 2, bark, name="trunk")
        leaves = b.material(foliage_material(rng))
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


def _hedges(b: SceneBuilder, rng, side: _Side, placer: Placer) -> None:
    for _ in range(rng.integers(3, 7)):
        hx = rng.uniform(X_LO, X_HI)
        hy = side.front - side.sign * 0.6
        if placer.free(hx, hy, 1.0):
            placer.take(hx, hy, 1.0)
            b.ellipsoid(
                (hx, hy, side.z0 + 0.5),
                (rng.uniform(1.0, 3.0), 0.5, 0.7),
                foliage_material(rng),
                name="hedge",
            )


def _parked_cars(b: SceneBuilder, rng, side: _Side, placer: Placer) -> None:
    """Cars parked along the kerb, some gaps left."""
    for cx in np.arange(X_LO + rng.uniform(0, 10), X_HI, rng.uniform(7.0, 14.0)):
        cy = side.edge - side.sign * 1.1
        if rng.random() < 0.3 or not placer.free(cx, cy, 2.4):
            continue
        placer.take(cx, cy, 2.4)
        _car(b, rng, cx, cy, side.z0)


def _car(b: SceneBuilder, rng, cx, cy, z0) -> None:
    """Body, cabin with windows, wheels, retro-reflective number plates at both ends."""
    paint = tuple(float(v) for v in rng.uniform(0.02, 0.7, 3))
    body = b.material(
        seeded_material(
            rng, "noise", 2.0, paint, jitter(rng, paint, 0.1), (0.3, 0.3), (0.05, 0.05, 0.5)
        )
    )
    b.box((cx, cy, z0 + 0.65), (2.1, 0.88, 0.35), body, name="car body")
    cabin = seeded_material(
        rng, "windows", 0.7, paint, (0.05, 0.07, 0.1), (0.3, 0.03), (0.05, 0.1, 0.5), dropout=0.6
    )
    b.box((cx - 0.2, cy, z0 + 1.25), (1.1, 0.78, 0.27), cabin, name="car cabin")
    for wx in (-1.35, 1.35):
        tyres = plain_material(rng, (0.03, 0.03, 0.03), 0.05)
        b.cylinder((cx + wx, cy, z0 + 0.32), 0.32, 0.93, tyres, axis=(0, 1, 0), name="wheels")
    for end in (-1, 1):
        plate = seeded_material(
            rng, "text", 0.1, (0.9, 0.9, 0.85), (0.05,) * 3, (3.0, 0.6), retro=True
        )
        b.rectangle(
            (cx + end * 2.11, cy, z0 + 0.6),
            (0, end, 0),
            UP,
            (0.26, 0.06),
            plate,
            name="number plate",
        )


def _bollards(b: SceneBuilder, rng, side: _Side, placer: Placer) -> None:
    """Bollards with balls on top, near the kerb around the rig."""
    z0 = side.z0
    for _ in range(rng.integers(2, 6)):
        bx = rng.uniform(-20.0, 40.0)
        by = side.edge + side.sign * 0.35
        if not placer.free(bx, by, 0.4):
            continue
        placer.take(bx, by, 0.4)
        stripes = seeded_material(rng, "stripes", 0.3, (0.8,) * 3, (0.1,) * 3, (0.6, 0.1))
        b.cylinder((bx, by, z0 + 0.45), 0.1, 0.45, stripes, axis=(0, 0, 1), name="bollard")
        ball = plain_material(rng, (0.7, 0.6, 0.1), 0.5)
        b.sphere((bx, by, z0 + 1.0), 0.12, ball, name="ball")


def _sunlight(rng) -> Lighting:
    """The sun 30 to 60 degrees up, from any direction."""
    elevation = rng.uniform(np.radians(30), np.radians(60))
    azimuth = rng.uniform(0, 2 * np.pi)
    sun = (
        math.cos(elevation) * math.cos(azimuth),
        math.cos(elevation) * math.sin(azimuth),
        math.sin(elevation),
    )
    return Lighting(sun_direction=sun, sun_irradiance=1.0, ambient=0.45)
