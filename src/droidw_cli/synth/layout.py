"""The room's layout: its size, the furniture, the walkers' bodies and their materials.

Everything here is geometry plus material *recipes* (functions that make a
texture on demand); :mod:`droidw_cli.synth.scene` packs the textures and
places the walkers on their paths.

Each part draws from its own random stream ``default_rng([seed, tag, …])``
so that, e.g., adding walkers does not change the room's textures.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import numpy as np

from droidw_cli.synth import textures as tx
from droidw_cli.synth.atlas import Material, face_normal, lambert

TAG_ROOM, TAG_FURNITURE, TAG_CAMERA, TAG_WALKER, TAG_PATH, TAG_NOISE = 1, 2, 3, 100, 200, 7
TAG_GAIN = 8  # exposure gain drift and flicker (synth.photometric)
WALL_MARGIN = 0.95  # walkers keep this far from the walls (furniture depth + body radius)


@dataclass(frozen=True, eq=False)
class BoxSpec:
    """A box before texturing: centre (in the world, or in the body frame for walker parts), half extents,
    per-face material recipes (None = never visible), baked shading factors and its texel density as a
    multiple of the scene's."""

    centre: np.ndarray
    half: np.ndarray
    materials: list
    shades: list
    seed: tuple[int, ...]
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    rho_scale: float = 1.0


def room_size(seed: int) -> np.ndarray:
    """[width (x), depth (y), height (z)] in metres: about 5.5 × 4.9 × 2.6."""
    rng = np.random.default_rng([seed, TAG_ROOM])
    return np.array([rng.uniform(5.2, 5.8), rng.uniform(4.6, 5.2), rng.uniform(2.5, 2.7)])


def room_spec(seed: int, room: np.ndarray) -> BoxSpec:
    """The room as a box seen from inside: plaster (or one brick) walls, planks or tiles, a ceiling."""
    rng = np.random.default_rng([seed, TAG_ROOM, 1])
    walls: list[Material] = [tx.plaster] * 4
    if rng.uniform() < 0.35:
        walls[int(rng.choice([0, 1, 3]))] = tx.bricks  # faces 0, 1 (x walls) or 3 (far wall)
    floor = tx.planks if rng.uniform() < 0.6 else tx.tiles
    materials = [walls[0], walls[1], walls[2], walls[3], floor, tx.ceiling]  # face 2 (y = 0) is behind the camera
    shades = [lambert(-face_normal(f)) for f in range(6)]
    centre = np.array([0.0, room[1] / 2, room[2] / 2])
    return BoxSpec(centre, room / 2, materials, shades, (seed, TAG_ROOM, 2))


def furniture_specs(seed: int, room: np.ndarray) -> list[BoxSpec]:
    """Cabinets and tables against the far and side walls, out of the walkers' way."""
    rng = np.random.default_rng([seed, TAG_FURNITURE])
    wid, dep, _ = room
    gap = 0.02
    boxes = []
    # far wall: one item in each half
    for side in (-1, 1):
        w, d, h = rng.uniform(0.7, 1.4), rng.uniform(0.35, 0.6), rng.uniform(0.75, 2.0)
        lo, hi = (-wid / 2 + 0.15 + w / 2, -0.1 - w / 2) if side < 0 else (0.1 + w / 2, wid / 2 - 0.15 - w / 2)
        x = rng.uniform(lo, max(lo, hi))
        boxes.append((np.array([x, dep - gap - d / 2, h / 2]), np.array([w, d, h]) / 2, 3))  # back face 3
    # side walls: one item each, in the part of the room the camera sees
    for side in (-1, 1):
        d, length, h = rng.uniform(0.35, 0.6), rng.uniform(0.8, 1.6), rng.uniform(0.7, 1.9)
        y = rng.uniform(1.9 + length / 2, max(1.9 + length / 2, dep - 0.8 - length / 2))
        x = side * (wid / 2 - gap - d / 2)
        boxes.append((np.array([x, y, h / 2]), np.array([d, length, h]) / 2, 0 if side < 0 else 1))
    specs = []
    for i, (c, half, hidden) in enumerate(boxes):
        base = tx.pick_colour(rng, tx.FURNITURE_COLOURS)
        mat = partial(tx.furniture, base=base)
        materials = [mat] * 6
        materials[hidden] = None
        materials[4] = None  # the underside
        shades = [lambert(face_normal(f)) for f in range(6)]
        specs.append(BoxSpec(c, half, materials, shades, (seed, TAG_FURNITURE, i)))
    return specs


def _body_side(h: int, w: int, rho: float, rng: np.random.Generator, *, shirt, pattern, other, trousers,
               leg_h: float) -> np.ndarray:
    top = tx.cloth(h, w, rho, rng, base=shirt, pattern=pattern, other=other)
    legs = tx.cloth(h, w, rho, rng, base=trousers, pattern=0)
    return tx.stack_rows([legs, top], [min(h, int(round(leg_h * rho)))])


def _head_side(h: int, w: int, rho: float, rng: np.random.Generator, *, tone, hair, hair_from: float) -> np.ndarray:
    face = tx.skin(h, w, rho, rng, tone=tone)
    top = tx.hair(h, w, rho, rng, colour=hair)
    return tx.stack_rows([face, top], [min(h, int(round(hair_from * h)))])


def walker_specs(seed: int, index: int) -> list[BoxSpec]:
    """A walker: a body box (legs and torso, ~0.5 × 0.3 × 1.45 m) with a head box on top, in body coordinates
    (x across the shoulders, y forward, z up from the floor).  Saturated clothes, unlike the room."""
    rng = np.random.default_rng([seed, TAG_WALKER + index])
    scale = rng.uniform(0.92, 1.08)
    bw, bd, bh = rng.uniform(0.44, 0.55) * scale, rng.uniform(0.25, 0.32) * scale, rng.uniform(1.36, 1.5) * scale
    hw, hd, hh = rng.uniform(0.19, 0.23), rng.uniform(0.21, 0.25), rng.uniform(0.24, 0.28)
    body = partial(_body_side, shirt=tx.pick_colour(rng, tx.CLOTH_COLOURS), pattern=int(rng.integers(4)),
                   other=tx.pick_colour(rng, tx.CLOTH_COLOURS + [(240, 240, 240), (25, 25, 25)]),
                   trousers=tx.pick_colour(rng, tx.TROUSER_COLOURS), leg_h=rng.uniform(0.5, 0.56) * bh)
    top = partial(tx.cloth, base=tx.pick_colour(rng, tx.CLOTH_COLOURS), pattern=0)
    hair_colour = tx.pick_colour(rng, tx.HAIR_COLOURS)
    head = partial(_head_side, tone=tx.pick_colour(rng, tx.SKIN_COLOURS), hair=hair_colour, hair_from=rng.uniform(0.55, 0.7))
    hair = partial(tx.hair, colour=hair_colour)
    shades = [lambert(face_normal(f)) for f in range(6)]
    body_spec = BoxSpec(np.array([0.0, 0.0, bh / 2]), np.array([bw, bd, bh]) / 2,
                        [body, body, body, body, None, top], shades, (seed, TAG_WALKER + index, 0))
    head_spec = BoxSpec(np.array([0.0, 0.02, bh + hh / 2]), np.array([hw, hd, hh]) / 2,
                        [head, head, hair, head, None, hair], shades, (seed, TAG_WALKER + index, 1))
    return [body_spec, head_spec]


def walker_region(room: np.ndarray, near_y: float) -> tuple[np.ndarray, np.ndarray]:
    """The floor rectangle (lo, hi) the walkers' paths stay in."""
    wid, dep, _ = room
    return np.array([-wid / 2 + WALL_MARGIN, near_y]), np.array([wid / 2 - WALL_MARGIN, dep - WALL_MARGIN])
