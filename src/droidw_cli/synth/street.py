"""A street for the forward-moving cameras: road, kerbs, sidewalks, buildings, lamp posts, parked cars, sky.

World frame as everywhere (x right, y along the street, z up, metres); the
road surface is z = 0, centred on x = 0, and the camera travels along +y
(:mod:`droidw_cli.synth.forward`).  Across the street, from the centre out:

    road (``road`` wide, asphalt, lanes) | kerb + sidewalk (0.12 m up) | facades at x = ±``facade``

The facades are separate buildings, each its own box: 6-25 m long, set back
0-1.2 m now and then, with alleys between some of them, 6-20 m tall (a
village street on ``forward``, a city road on ``drive``).  The street ends
in a building across it well beyond the camera's last position.  An outer
box (seen from inside) closes the world: low backyard walls and ground behind
the buildings, and an open top, the sky (:class:`~droidw_cli.synth.raycast.Box`
``sky``), at infinite depth.  Lamp posts stand on both kerbs; parked cars
line the kerbs where the road has parking.

Texel density: a box whose near end lies more than 40 m (100 m) beyond the
camera's last position is only ever seen from afar and gets half (a quarter)
of the texels; the outer box gets a quarter.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from droidw_cli.synth import street_textures as st
from droidw_cli.synth import textures as tx
from droidw_cli.synth.atlas import face_normal, lambert
from droidw_cli.synth.layout import BoxSpec

TAG_STREET, TAG_BUILDING, TAG_FURNISH = 11, 12, 13
KERB = 0.12  # m: the sidewalk above the road
SLAB = 0.3  # m: the road and sidewalk slabs' thickness (the outer ground lies below them)
SEGMENT = 40.0  # m: road and sidewalks are cut into pieces this long (texel density by distance)
OUTER_WALL = 3.0  # m: the backyard walls of the outer box


@dataclass(frozen=True)
class StreetPlan:
    """The street's cross-section and length (metres); ``lane_x`` is the camera's line."""

    road: float
    walk: float
    lanes: int
    parking: bool
    lane_x: float
    heights: tuple[float, float]
    lengths: tuple[float, float]
    far: float  # the street's end lies this far beyond the camera's last position

    @property
    def facade(self) -> float:
        return self.road / 2 + self.walk


def street_plan(motion: str, seed: int) -> StreetPlan:
    """The street of a ``forward`` walk (on the right sidewalk), a ``ride`` (the right edge of the road), a
    ``drive`` (the right lane of a two-lane road with parking) or a follow shot (``follow``, ``follow-pan``:
    :mod:`~droidw_cli.synth.follow`)."""
    rng = np.random.default_rng([seed, TAG_STREET])
    if motion == "forward":
        road, walk = rng.uniform(5.5, 7.0), rng.uniform(2.6, 3.4)
        return StreetPlan(road, walk, 2, rng.uniform() < 0.5, road / 2 + walk * rng.uniform(0.4, 0.55),
                          (6.0, 16.0), (6.0, 18.0), 35.0)
    if motion == "ride":
        road, walk = rng.uniform(7.0, 9.0), rng.uniform(2.5, 3.5)
        return StreetPlan(road, walk, 2, False, road / 2 - rng.uniform(1.9, 2.3), (7.0, 18.0), (8.0, 22.0), 60.0)
    if motion == "follow":  # wide sidewalks, no parking: lane_x is the subject's line, mid-sidewalk
        road, walk = rng.uniform(5.5, 7.0), rng.uniform(3.6, 4.4)
        return StreetPlan(road, walk, 2, False, road / 2 + walk / 2, (6.0, 16.0), (6.0, 18.0), 35.0)
    if motion == "follow-pan":  # the camera walks the outer part of the sidewalk, the subject passes on the road
        road, walk = rng.uniform(6.0, 8.0), rng.uniform(2.6, 3.4)
        return StreetPlan(road, walk, 2, False, road / 2 + walk * rng.uniform(0.6, 0.75), (6.0, 16.0), (6.0, 18.0),
                          35.0)
    road, walk = 11.4, rng.uniform(3.0, 4.0)  # two 3.5 m lanes and two 2.2 m parking strips
    return StreetPlan(road, walk, 2, True, 1.75, (6.0, 20.0), (10.0, 25.0), 120.0)


def _density(y_near: float, y_last: float) -> float:
    beyond = y_near - y_last
    return 1.0 if beyond < 40.0 else (0.5 if beyond < 100.0 else 0.25)


def _box(centre, half, materials, seed, rho_scale: float = 1.0, rotation=None, inside: bool = False) -> BoxSpec:
    rotation = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
    shades = [lambert((-1.0 if inside else 1.0) * rotation @ face_normal(f)) for f in range(6)]
    return BoxSpec(np.asarray(centre, np.float64), np.asarray(half, np.float64), materials, shades, seed, rotation,
                   rho_scale)


def outer_box(plan: StreetPlan, seed: int, y0: float, y1: float) -> BoxSpec:
    """The world's closing box seen from inside: backyard ground and walls (coarse), its top the sky."""
    half_x = plan.facade + 14.0
    centre = (0.0, (y0 + y1) / 2, (OUTER_WALL - SLAB) / 2)
    half = (half_x, (y1 - y0) / 2, (OUTER_WALL + SLAB) / 2)
    materials = [tx.plaster, tx.plaster, None, tx.plaster, tx.tiles, None]  # face 5 (the top) is the sky
    return _box(centre, half, materials, (seed, TAG_STREET, 1), 0.25, inside=True)


def ground_specs(plan: StreetPlan, seed: int, y0: float, y1: float, y_last: float) -> list[BoxSpec]:
    """Road and sidewalk slabs in pieces of at most ``SEGMENT`` metres along the street."""
    out = []
    n = int(np.ceil((y1 - y0) / SEGMENT))
    edges = np.linspace(y0, y1, n + 1)
    road = partial(st.asphalt, lanes=plan.lanes + 2 * plan.parking)
    walk_w = plan.walk + 1.5  # the sidewalk runs on under the set-back buildings
    for i, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        scale = _density(a, y_last)
        half_y, cy = (b - a) / 2, (a + b) / 2
        out.append(_box((0.0, cy, -SLAB / 2), (plan.road / 2, half_y, SLAB / 2), [None] * 5 + [road],
                        (seed, TAG_STREET, 10, i), scale))
        for side in (-1, 1):
            x = side * (plan.road / 2 + walk_w / 2)
            mats = [None] * 6
            mats[0 if side > 0 else 1] = st.kerb_stone  # the face towards the road
            mats[5] = tx.tiles
            out.append(_box((x, cy, (KERB - SLAB) / 2), (walk_w / 2, half_y, (KERB + SLAB) / 2), mats,
                            (seed, TAG_STREET, 11 + side, i), scale))
    return out


def building_specs(plan: StreetPlan, seed: int, y0: float, y_end: float, y_last: float) -> list[BoxSpec]:
    """The buildings along both sides from y0 to y_end, and the one across the street's end."""
    rng = np.random.default_rng([seed, TAG_BUILDING])
    out = []
    for side in (-1, 1):
        y = y0
        while y < y_end:
            length = rng.uniform(*plan.lengths)
            height = rng.uniform(*plan.heights)
            setback = rng.uniform(0.3, 1.2) if rng.uniform() < 0.3 else 0.0
            depth = rng.uniform(6.0, 10.0)
            b = min(y + length, y_end)
            x = side * (plan.facade + setback + depth / 2)
            mats = [tx.plaster, tx.plaster, tx.plaster, tx.plaster, None, None]
            mats[0 if side > 0 else 1] = st.facade  # the front faces the street
            mats[1 if side > 0 else 0] = None  # the back
            out.append(_box((x, (y + b) / 2, height / 2), (depth / 2, (b - y) / 2, height / 2), mats,
                            (seed, TAG_BUILDING, 1 + side, len(out)), _density(y, y_last)))
            y = b + (rng.uniform(2.0, 5.0) if rng.uniform() < 0.25 else 0.0)  # an alley now and then
    width = plan.facade + 14.0
    height = rng.uniform(*plan.heights)
    mats = [None, None, st.facade, None, None, None]
    out.append(_box((0.0, y_end + 5.0, height / 2), (width, 5.0, height / 2), mats, (seed, TAG_BUILDING, 0, 0),
                    _density(y_end, y_last)))
    return out


def start_building(plan: StreetPlan, seed: int, y_start: float) -> BoxSpec:
    """A building across the street behind its start (its front, at y_start, faces +y): the end of the street
    that a camera looking back sees (the follow shots, :mod:`~droidw_cli.synth.follow`)."""
    height = np.random.default_rng([seed, TAG_BUILDING, 1]).uniform(*plan.heights)
    mats = [None, None, None, st.facade, None, None]
    return _box((0.0, y_start - 5.0, height / 2), (plan.facade + 14.0, 5.0, height / 2), mats,
                (seed, TAG_BUILDING, 3, 0))


def _car_parts(rng: np.random.Generator, seed: tuple[int, ...]) -> list[BoxSpec]:
    """A car in body coordinates (x across, y forward, z up from the road): a body and a glazed cabin."""
    paint = tx.pick_colour(rng, st.CAR_PAINT)
    length, width = rng.uniform(3.9, 4.7), rng.uniform(1.7, 1.85)
    body_h, cab_h = rng.uniform(0.75, 0.9), rng.uniform(0.5, 0.65)
    body = partial(st.car_paint, base=paint)
    glass = partial(st.car_glass, base=paint)
    roof = partial(st.car_paint, base=paint)
    specs = [_box((0.0, 0.0, 0.3 + body_h / 2), (width / 2, length / 2, body_h / 2), [body] * 4 + [None, body],
                  (*seed, 0)),
             _box((0.0, -0.1 * length, 0.3 + body_h + cab_h / 2), (0.46 * width, 0.27 * length, cab_h / 2),
                  [glass] * 4 + [None, roof], (*seed, 1))]
    return specs


def car_parts(seed: int, index: int) -> list[BoxSpec]:
    """The parts of moving car ``index`` (body coordinates)."""
    return _car_parts(np.random.default_rng([seed, TAG_FURNISH, 1000 + index]), (seed, TAG_FURNISH, 1000 + index))


def furnishing_specs(plan: StreetPlan, seed: int, y0: float, y_end: float, y_last: float) -> list[BoxSpec]:
    """Lamp posts on both kerbs and, where the road has parking, cars parked along them (world boxes)."""
    rng = np.random.default_rng([seed, TAG_FURNISH])
    out = []
    for side in (-1, 1):
        y = y0 + rng.uniform(0.0, 15.0)
        while y < y_end:
            x = side * (plan.road / 2 + 0.45)
            out.append(_box((x, y, KERB + 2.3), (0.07, 0.07, 2.3), [st.metal] * 4 + [None, st.metal],
                            (seed, TAG_FURNISH, 1 + side, len(out)), _density(y, y_last)))
            y += rng.uniform(15.0, 25.0)
    if plan.parking:
        for side in (-1, 1):
            y = y0 + rng.uniform(0.0, 8.0)
            while y < y_end - 5.0:
                length = 4.5
                if rng.uniform() < 0.7:
                    x = side * (plan.road / 2 - 1.1)
                    turn = np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]]) if side < 0 else np.eye(3)
                    for part in _car_parts(rng, (seed, TAG_FURNISH, 500 + side, len(out))):
                        centre = np.array([x, y + length / 2, 0.0]) + turn @ part.centre
                        out.append(_box(centre, part.half, part.materials, part.seed, _density(y, y_last), turn))
                y += length + rng.uniform(0.6, 3.0)
    return out
