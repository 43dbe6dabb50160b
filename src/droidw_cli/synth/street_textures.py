"""Procedural materials of a street: facades with windows, asphalt with lane markings, sky, cars, poles.

Same contract as :mod:`droidw_cli.synth.textures`: ``(h, w, rho, rng) ->
float32 (h, w, 3)`` RGB in 0..255, rows along the face's v axis ("up" on
vertical faces, the street's length on the road), sizes in metres through
``rho`` texels per metre.  Every material keeps texture at all scales (the
fractal noise of :func:`~droidw_cli.synth.textures.fbm`): windows and lane
dashes repeat, as they do in streets, but never exactly.
"""

from __future__ import annotations

import numpy as np

from droidw_cli.synth import textures as tx

ASPHALT = [(92, 92, 94), (78, 80, 84), (104, 100, 96)]
CAR_PAINT = [(180, 30, 30), (30, 60, 150), (220, 220, 215), (35, 35, 38), (150, 152, 158), (25, 110, 60),
             (200, 160, 30)]
FACADE_COLOURS = tx.WALL_COLOURS + [(150, 140, 128), (226, 214, 190), (170, 120, 96)]
SKY_HORIZON, SKY_ZENITH = (214, 224, 236), (110, 150, 205)


def _grid_cells(n: int, period: float, size: float, start: float) -> tuple[np.ndarray, np.ndarray]:
    """Per texel index along an axis: which cell it is in (−1 outside a window) and where in the cell (0..1)."""
    pos = (np.arange(n, dtype=np.float32) + 0.5 - start) / period
    cell = np.floor(pos).astype(np.int64)
    frac = (pos - cell) * period / size
    inside = (pos >= 0) & (frac < 1.0)
    return np.where(inside, cell, -1), frac


def facade(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """A building front: plaster or brick, storeys of windows (dark glass with framing, some lit or shaded),
    a ground floor of shop windows or a door band, noise at every scale."""
    wall = tx.bricks(h, w, rho, rng) if rng.uniform() < 0.35 else \
        tx._colour(tx.pick_colour(rng, FACADE_COLOURS), tx.fbm(h, w, rng, 0.8 * rho, gain=0.72), 0.14,
                   tx._chroma(h, w, rng, rho, 8.0))
    storey, bay = rng.uniform(2.9, 3.5) * rho, rng.uniform(2.2, 3.6) * rho
    win_h, win_w = rng.uniform(0.45, 0.6) * storey, rng.uniform(0.35, 0.6) * bay
    rows, fv = _grid_cells(h, storey, win_h, storey + 0.3 * storey)  # v up: the first storey is the ground floor
    cols, fu = _grid_cells(w, bay, win_w, rng.uniform(0.2, 0.8) * bay)
    n_r, n_c = max(1, int(h / storey) + 2), max(1, int(w / bay) + 2)
    tone = rng.uniform(-0.5, 0.6, (n_r, n_c)).astype(np.float32)  # per-window glass brightness
    shut = rng.uniform(size=(n_r, n_c)) < 0.15  # closed shutters
    glass = np.stack([tx.fbm(h, w, rng, 0.5 * rho, gain=0.8) for _ in range(3)], -1) * np.float32(14.0)
    base = np.float32(55.0) + np.float32(40.0) * tone[np.maximum(rows, 0)[:, None], np.maximum(cols, 0)[None, :]]
    pane = base[..., None] + glass + np.array([0.0, 4.0, 12.0], np.float32)
    border = (fv[:, None] < 0.06) | (fv[:, None] > 0.94) | (fu[None, :] < 0.07) | (fu[None, :] > 0.93)
    mullion = np.abs(fu[None, :] - 0.5) < 0.025
    frame = np.float32(235.0) - np.float32(20.0) * tx.fbm(h, w, rng, 0.1 * rho)[..., None]
    is_win = (rows[:, None] >= 0) & (cols[None, :] >= 0)
    shutter = shut[np.maximum(rows, 0)[:, None], np.maximum(cols, 0)[None, :]] & is_win
    out = np.where(is_win[..., None], np.where((border | mullion)[..., None], frame, pane), wall)
    slats = (np.arange(h, dtype=np.float32)[:, None] % max(2.0, 0.06 * rho)) < max(1.0, 0.015 * rho)
    out = np.where(shutter[..., None], np.where(slats[..., None], 70.0, 150.0) + glass * 0.5, out)
    ground = int(round(storey))  # a ground floor band: shop windows with signs above
    if ground < h:
        shop = np.float32(65.0) + np.float32(30.0) * tx.fbm(ground, w, rng, 0.3 * rho, gain=0.75)[..., None] \
            + tx._chroma(ground, w, rng, 0.5 * rho, 10.0)
        sign = int(0.25 * ground)
        band = tx.pick_colour(rng, tx.CLOTH_COLOURS) * (1.0 + 0.1 * tx.fbm(sign, w, rng, 0.2 * rho))[..., None]
        piers = _grid_cells(w, rng.uniform(4.0, 7.0) * rho, rng.uniform(3.0, 3.6) * rho, 0.5 * rho)[0] < 0
        lower = np.where(piers[None, :, None], out[:ground], shop)
        lower[ground - sign:] = band
        lower[: max(1, int(0.05 * ground))] = 90.0  # a plinth
        out[:ground] = lower
    return out


def asphalt(h: int, w: int, rho: float, rng: np.random.Generator, lanes: int = 2) -> np.ndarray:
    """A road: asphalt noise and patches, solid edge lines and dashed lane lines along v (the road's length)."""
    lum = 0.6 * tx.fbm(h, w, rng, 0.5 * rho, gain=0.75) + 0.4 * tx.fbm(h, w, rng, 0.04 * rho, min_cell=1.0)
    lum -= 0.3 * tx._stains(h, w, rng, 1.2 * rho, 0.15)
    img = tx._colour(tx.pick_colour(rng, ASPHALT), lum, 0.14)
    u = np.arange(w, dtype=np.float32) / rho  # metres across
    v = np.arange(h, dtype=np.float32) / rho  # metres along
    width = w / rho
    line = 0.12
    edge = (np.abs(u - 0.3) < line / 2) | (np.abs(u - (width - 0.3)) < line / 2)
    dash_len, gap = rng.uniform(2.5, 3.5), rng.uniform(4.0, 6.0)
    dashed = np.mod(v - rng.uniform(0, dash_len + gap), dash_len + gap) < dash_len
    marks = np.zeros((h, w), bool) | edge[None, :]
    for k in range(1, lanes):
        marks |= (np.abs(u - k * width / lanes) < line / 2)[None, :] & dashed[:, None]
    paint = np.float32(225.0) * (1.0 + 0.06 * tx.fbm(h, w, rng, 0.05 * rho, min_cell=1.0))
    return np.where(marks[..., None], paint[..., None], img)


def kerb_stone(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """A granite kerb: light grey with speckle."""
    return tx._colour((170, 168, 162), tx.fbm(h, w, rng, 0.1 * rho, min_cell=1.0), 0.12)


def sky(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """The sky panel (rows: elevation from the horizon up): a horizon-to-zenith gradient with faint clouds."""
    e = (np.arange(h, dtype=np.float32) / max(1, h - 1))[:, None, None]
    grad = (1 - e) * np.asarray(SKY_HORIZON, np.float32) + e * np.asarray(SKY_ZENITH, np.float32)
    clouds = np.clip(tx.fbm(h, w, rng, w / 12.0, gain=0.55) - 0.6, 0, None)[..., None]
    return grad + np.float32(30.0) * clouds * (255.0 - grad) / 255.0


def car_paint(h: int, w: int, rho: float, rng: np.random.Generator, base=None) -> np.ndarray:
    """A car body panel: glossy paint (smooth, low contrast) with a dark bumper strip and reflections."""
    base = tx.pick_colour(rng, CAR_PAINT) if base is None else np.asarray(base, np.float32)
    img = tx._colour(base, tx.fbm(h, w, rng, 0.4 * rho, gain=0.6), 0.10, tx._chroma(h, w, rng, 0.5 * rho, 6.0))
    strip = max(1, int(0.18 * rho))
    img[:strip] = np.float32(40.0) + np.float32(10.0) * tx.fbm(strip, w, rng, 0.1 * rho)[..., None]
    return img


def car_glass(h: int, w: int, rho: float, rng: np.random.Generator, base=None) -> np.ndarray:
    """Car windows: dark glass with a painted frame (``base``) and streaky reflections."""
    base = tx.pick_colour(rng, CAR_PAINT) if base is None else np.asarray(base, np.float32)
    lum = tx.fbm(h, w, rng, 0.3 * rho, gain=0.7, aspect=0.3)
    img = np.float32(50.0) + np.float32(30.0) * lum[..., None] + np.array([0.0, 3.0, 9.0], np.float32)
    b = max(1, int(0.06 * rho))
    img[:b], img[-b:], img[:, :b], img[:, -b:] = base, base, base, base
    return img


def metal(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """A painted metal pole: dark grey-green with rust spots."""
    return tx._colour((72, 82, 76), tx.fbm(h, w, rng, 0.2 * rho, gain=0.7) - 0.4 * tx._stains(h, w, rng, 0.1 * rho, 0.1),
                      0.2)
