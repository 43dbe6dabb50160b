"""A texture atlas: every box face gets its own rectangle of texels in one image.

A face of a box with half extents h, normal axis k, spans 2h[u(k)] × 2h[v(k)]
metres (face axes as in :mod:`droidw_cli.synth.raycast`) and gets
⌈2h·ρ⌉ + 1 texels per side.  Rectangles are shelf-packed (tallest first) into
one uint8 RGB image so that one ``cv2.remap`` textures a whole frame.  Faces
that can never be seen (the underside of a walker, the back of a cabinet
against a wall) get a 2 × 2 placeholder.

Shading is baked in: each face's texture is multiplied by
ambient + (1 − ambient)·max(0, n·ℓ) for its outward normal n (inward for the
room) and a fixed light direction ℓ — Lambertian, so it does not depend on
the viewpoint and static pixels keep their colour from frame to frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

U_AXIS = (1, 0, 0)
V_AXIS = (2, 2, 1)
LIGHT = np.array([0.35, -0.55, 0.76]) / np.linalg.norm([0.35, -0.55, 0.76])
AMBIENT = 0.62
MAX_SIDE = 32000  # cv2.remap needs source images below 32767 pixels a side

Material = Callable[[int, int, float, np.random.Generator], np.ndarray]


def face_normal(f: int) -> np.ndarray:
    """Outward normal of face f = 2k + s in box coordinates."""
    n = np.zeros(3)
    n[f // 2] = 1.0 if f % 2 else -1.0
    return n


def lambert(normal_world: np.ndarray) -> float:
    return float(AMBIENT + (1.0 - AMBIENT) * max(0.0, float(normal_world @ LIGHT)))


@dataclass
class _Request:
    w: int
    h: int
    material: Material | None
    seed: tuple[int, ...]
    shade: float
    group: int
    rho: float


class AtlasBuilder:
    """Collects face textures, packs them and renders the atlas."""

    def __init__(self, rho: float):
        self.rho = float(rho)
        self._requests: list[_Request] = []
        self._boxes: list[list[int]] = []

    def add_box(self, half: np.ndarray, materials: list[Material | None], shades: list[float],
                seed: tuple[int, ...], group: int = 0, rho_scale: float = 1.0) -> int:
        """Register the 6 faces of a box; returns a handle for :meth:`build`'s tables.

        Groups are packed one after the other (group 0 on top, its width fixing
        the atlas width), so the layout of group 0 does not depend on later groups.
        ``rho_scale``: this box's texel density is ``rho · rho_scale`` (the caster
        must be given it: :attr:`droidw_cli.synth.raycast.Box.rho`).
        """
        rho = self.rho * rho_scale
        ids = []
        for f in range(6):
            k = f // 2
            if materials[f] is None:
                w = h = 2
            else:
                w = int(np.ceil(2 * half[U_AXIS[k]] * rho)) + 1
                h = int(np.ceil(2 * half[V_AXIS[k]] * rho)) + 1
            ids.append(len(self._requests))
            self._requests.append(_Request(w, h, materials[f], (*seed, f), float(shades[f]), int(group), rho))
        self._boxes.append(ids)
        return len(self._boxes) - 1

    def add_panel(self, width: int, height: int, material: Material, seed: tuple[int, ...], group: int = 0) -> int:
        """Register one free-standing texture of ``width`` × ``height`` texels (the sky); returns a handle
        for :meth:`build`'s tables, whose table is then (1, 4)."""
        self._requests.append(_Request(int(width), int(height), material, seed, 1.0, int(group), self.rho))
        self._boxes.append([len(self._requests) - 1])
        return len(self._boxes) - 1

    def build(self) -> tuple[np.ndarray, list[np.ndarray]]:
        """The atlas (H, W, 3) uint8 and, per box (panel), its (6, 4) ((1, 4)) float32 table (ox, oy, w − 1, h − 1)."""
        reqs = self._requests
        first = min(r.group for r in reqs)
        total = sum(r.w * r.h for r in reqs if r.group == first)
        width = max(max(r.w for r in reqs), int(np.ceil(np.sqrt(total * 1.2))))
        pos: dict[int, tuple[int, int]] = {}
        y = 0
        for group in sorted({r.group for r in reqs}):
            order = sorted((i for i, r in enumerate(reqs) if r.group == group), key=lambda i: (-reqs[i].h, i))
            x = shelf = 0
            for i in order:
                r = reqs[i]
                if x + r.w > width:
                    x, y, shelf = 0, y + shelf, 0
                pos[i] = (x, y)
                x += r.w
                shelf = max(shelf, r.h)
            y += shelf
        height = y
        if width > MAX_SIDE or height > MAX_SIDE:
            raise ValueError(f"texture atlas too large ({width}x{height}); lower texel_density")
        atlas = np.full((height, width, 3), 128, np.uint8)
        for i, r in enumerate(reqs):
            if r.material is None:
                continue
            ox, oy = pos[i]
            tex = r.material(r.h, r.w, r.rho, np.random.default_rng(list(r.seed)))
            tex = tex * np.float32(r.shade)
            atlas[oy:oy + r.h, ox:ox + r.w] = np.clip(np.rint(tex), 0, 255).astype(np.uint8)
        tables = []
        for ids in self._boxes:
            t = np.array([[pos[i][0], pos[i][1], reqs[i].w - 1, reqs[i].h - 1] for i in ids], np.float32)
            tables.append(t)
        return atlas, tables
