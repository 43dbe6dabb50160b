"""Procedural textures: multi-octave value noise, planks, tiles, bricks, cloth.

Every material is a function ``(h, w, rho, rng) -> float32 (h, w, 3)`` RGB in
0..255, where ``h × w`` texels cover ``h/rho × w/rho`` metres (rows follow the
face's v axis, which is "up" on vertical faces).  Physical sizes (plank width,
tile size, stripe width) are in metres and converted with ``rho``.

Value noise: an octave with lattice spacing c texels is a grid of standard
normal values interpolated bicubically (``cv2.resize``).  Fractal noise sums
octaves c, c/2, c/4, … down to 2 texels with amplitudes g⁰, g¹, g², … and is
normalised to unit standard deviation, so a texture carries photometric
variation from decimetres down to the pixel scale — what dense optical flow
needs — without a periodic pattern that could alias.
"""

from __future__ import annotations

import cv2
import numpy as np

MIN_CELL = 2.0  # finest lattice spacing in texels
COARSE = 4  # coarse octaves are computed on a grid this many times smaller


def value_noise(h: int, w: int, cell: float, rng: np.random.Generator, aspect: float = 1.0) -> np.ndarray:
    """One octave of value noise, (h, w) float32; lattice spacing ``cell`` texels along x, ``cell*aspect`` along y."""
    cx, cy = max(float(cell), 1.0), max(float(cell) * aspect, 1.0)
    gh, gw = int(np.ceil(h / cy)) + 4, int(np.ceil(w / cx)) + 4
    grid = rng.standard_normal((gh, gw)).astype(np.float32)
    big = cv2.resize(grid, (int(round(gw * cx)), int(round(gh * cy))), interpolation=cv2.INTER_CUBIC)
    oy, ox = int(round(1.5 * cy)), int(round(1.5 * cx))
    return big[oy:oy + h, ox:ox + w]


def fbm(h: int, w: int, rng: np.random.Generator, cell: float, gain: float = 0.6,
        min_cell: float = MIN_CELL, aspect: float = 1.0) -> np.ndarray:
    """Fractal value noise with octaves cell, cell/2, … ≥ min_cell (texels), unit std, (h, w) float32.

    Octaves whose lattice spacing is ≥ 4·COARSE texels are summed on a grid
    COARSE times smaller and upsampled once (bilinearly): they are smooth at
    that scale, and this keeps the cost near that of the fine octaves alone.
    """
    out = np.zeros((h, w), np.float32)
    hc, wc = -(-h // COARSE) + 1, -(-w // COARSE) + 1
    coarse = np.zeros((hc, wc), np.float32)
    amp, c, any_coarse = 1.0, float(cell), False
    while True:
        if min(c, c * aspect) >= 4 * COARSE:
            coarse += np.float32(amp) * value_noise(hc, wc, c / COARSE, rng, aspect)
            any_coarse = True
        else:
            out += np.float32(amp) * value_noise(h, w, c, rng, aspect)
        c *= 0.5
        amp *= gain
        if c < min_cell:
            break
    if any_coarse:
        up = cv2.resize(coarse, (wc * COARSE, hc * COARSE), interpolation=cv2.INTER_LINEAR)
        out += up[:h, :w]
    std = float(out.std())
    return out / np.float32(std if std > 1e-6 else 1.0)


def _colour(base, lum: np.ndarray, contrast: float, chroma: np.ndarray | None = None) -> np.ndarray:
    """base·(1 + contrast·lum) (+ per-channel chroma offsets), (h, w, 3) float32."""
    base = np.asarray(base, np.float32)
    out = (1.0 + np.float32(contrast) * lum)[..., None] * base
    if chroma is not None:
        out += chroma
    return out


def _chroma(h: int, w: int, rng: np.random.Generator, cell: float, amount: float) -> np.ndarray:
    """Slow colour drift: three independent coarse noise channels (h, w, 3), ± amount grey levels."""
    return np.stack([fbm(h, w, rng, cell, min_cell=max(cell / 4, MIN_CELL)) for _ in range(3)], -1) * np.float32(amount)


def _stains(h: int, w: int, rng: np.random.Generator, cell: float, frac: float) -> np.ndarray:
    """A 0/1 float mask of blotches with sharp borders covering about ``frac`` of the area."""
    n = fbm(h, w, rng, cell)
    thr = np.quantile(n[:: max(1, h // 64), :: max(1, w // 64)], 1.0 - frac)
    return (n > thr).astype(np.float32)


def pick_colour(rng: np.random.Generator, palette) -> np.ndarray:
    return np.asarray(palette[int(rng.integers(len(palette)))], np.float32) * np.float32(rng.uniform(0.9, 1.1))


WALL_COLOURS = [(214, 200, 178), (190, 196, 188), (205, 190, 170), (172, 186, 198), (200, 172, 152), (186, 182, 196)]
WOOD_COLOURS = [(150, 105, 65), (122, 86, 56), (176, 136, 92), (105, 72, 48)]
STONE_COLOURS = [(182, 180, 172), (142, 150, 160), (170, 160, 140), (120, 118, 112)]
FURNITURE_COLOURS = [(110, 80, 55), (92, 96, 106), (62, 80, 110), (160, 150, 128), (120, 60, 50), (70, 95, 70)]
CLOTH_COLOURS = [(205, 30, 40), (30, 155, 60), (40, 70, 210), (235, 185, 20), (155, 40, 175), (245, 115, 20),
                 (20, 175, 195), (230, 60, 140)]
TROUSER_COLOURS = [(30, 38, 70), (75, 60, 40), (20, 70, 130), (120, 100, 62), (55, 55, 58), (90, 20, 30)]
SKIN_COLOURS = [(228, 182, 150), (196, 142, 102), (146, 98, 66), (100, 68, 46)]
HAIR_COLOURS = [(42, 30, 20), (96, 62, 30), (22, 20, 20), (205, 172, 112), (140, 60, 30)]


def plaster(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """A painted wall: mottled multi-scale noise, stains and a few framed pictures."""
    base = pick_colour(rng, WALL_COLOURS)
    lum = fbm(h, w, rng, 0.6 * rho, gain=0.72)
    img = _colour(base, lum, 0.16, _chroma(h, w, rng, 1.0 * rho, 8.0))
    img *= (1.0 - 0.22 * _stains(h, w, rng, 0.25 * rho, 0.12))[..., None]
    for _ in range(int(rng.integers(1, 4))):
        _picture(img, rho, rng)
    return img


def _picture(img: np.ndarray, rho: float, rng: np.random.Generator) -> None:
    """Paint a framed picture (colourful noise) into ``img`` at a random place, in place."""
    h, w = img.shape[:2]
    ph, pw = int(rng.uniform(0.35, 0.9) * rho), int(rng.uniform(0.35, 1.1) * rho)
    if ph + 4 >= h or pw + 4 >= w:
        return
    y0 = int(rng.integers(int(0.25 * h), max(int(0.25 * h) + 1, h - ph - 1)))
    x0 = int(rng.integers(0, w - pw))
    b = max(2, int(0.025 * rho))
    art = np.stack([fbm(ph, pw, rng, rng.uniform(0.08, 0.3) * rho, gain=0.7) for _ in range(3)], -1)
    art = 128.0 + 55.0 * art + rng.uniform(-40, 40, 3).astype(np.float32)
    frame = pick_colour(rng, [(30, 25, 20), (200, 170, 90), (240, 240, 235), (60, 40, 30)])
    img[y0:y0 + ph, x0:x0 + pw] = frame
    img[y0 + b:y0 + ph - b, x0 + b:x0 + pw - b] = art[b:ph - b, b:pw - b]


def ceiling(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """A light ceiling, still textured enough for flow."""
    lum = fbm(h, w, rng, 0.5 * rho, gain=0.7)
    return _colour(pick_colour(rng, [(226, 224, 218), (214, 216, 220)]), lum, 0.12, _chroma(h, w, rng, rho, 5.0))


def planks(h: int, w: int, rho: float, rng: np.random.Generator, base=None) -> np.ndarray:
    """Wooden planks along the u axis, random widths and joints, per-plank tint, anisotropic grain."""
    base = pick_colour(rng, WOOD_COLOURS) if base is None else np.asarray(base, np.float32)
    widths = rng.uniform(0.1, 0.2, size=int(h / (0.1 * rho)) + 2) * rho
    edges = np.cumsum(widths)
    row_id = np.searchsorted(edges, np.arange(h) + 0.5)
    n = len(edges) + 1
    length = rng.uniform(0.7, 1.6, n) * rho
    offset = rng.uniform(0, 1, n) * length
    cols = np.arange(w, dtype=np.float32)[None, :]
    pos = cols + offset[row_id][:, None]
    seg = np.floor(pos / length[row_id][:, None]).astype(np.int64)
    tint = rng.uniform(-0.18, 0.18, (n, int(w / (0.7 * rho)) + 3)).astype(np.float32)
    lum = tint[row_id[:, None], np.minimum(seg, tint.shape[1] - 1)]
    grain = fbm(h, w, rng, 0.4 * rho, gain=0.75, aspect=0.06)
    lum = lum + 0.14 * grain + 0.08 * fbm(h, w, rng, 0.15 * rho)
    gap = max(1.0, 0.004 * rho)
    in_row = np.arange(h) + 0.5 - np.concatenate([[0.0], edges])[row_id]
    dark = (in_row < gap)[:, None] | ((pos - seg * length[row_id][:, None]) < gap)
    lum = np.where(dark, np.float32(-0.55), lum)
    return _colour(base, lum, 1.0, _chroma(h, w, rng, rho, 6.0))


def tiles(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """Square tiles with per-tile tint, grout lines and surface noise."""
    base = pick_colour(rng, STONE_COLOURS)
    size = rng.uniform(0.25, 0.45) * rho
    vv, uu = np.arange(h, dtype=np.float32)[:, None], np.arange(w, dtype=np.float32)[None, :]
    iv, iu = np.floor(vv / size).astype(np.int64), np.floor(uu / size).astype(np.int64)
    tint = rng.uniform(-0.15, 0.15, (int(h / size) + 2, int(w / size) + 2)).astype(np.float32)
    lum = tint[iv, iu] + 0.12 * fbm(h, w, rng, 0.3 * rho, gain=0.7)
    gap = max(1.0, 0.006 * rho)
    grout = ((vv - iv * size) < gap) | ((uu - iu * size) < gap)
    lum = np.where(grout, np.float32(-0.45), lum)
    return _colour(base, lum, 1.0, _chroma(h, w, rng, rho, 6.0))


def bricks(h: int, w: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """Running-bond bricks (alternate rows offset by half a brick), mortar, per-brick tint."""
    base = pick_colour(rng, [(160, 80, 60), (140, 96, 72), (180, 120, 90)])
    bh, bw, mortar = 0.085 * rho, 0.23 * rho, max(1.0, 0.01 * rho)
    vv, uu = np.arange(h, dtype=np.float32)[:, None], np.arange(w, dtype=np.float32)[None, :]
    row = np.floor(vv / bh).astype(np.int64)
    uo = uu + (row % 2) * (0.5 * bw)
    col = np.floor(uo / bw).astype(np.int64)
    tint = rng.uniform(-0.2, 0.2, (int(h / bh) + 2, int(w / bw) + 3)).astype(np.float32)
    lum = tint[row, col] + 0.15 * fbm(h, w, rng, 0.12 * rho, gain=0.7)
    joint = ((vv - row * bh) < mortar) | ((uo - col * bw) < mortar)
    img = _colour(base, lum, 1.0, _chroma(h, w, rng, rho, 8.0))
    grey = np.float32(150.0) * (1.0 + 0.1 * fbm(h, w, rng, 0.05 * rho))
    return np.where(joint[..., None], grey[..., None], img)


def furniture(h: int, w: int, rho: float, rng: np.random.Generator, base=None) -> np.ndarray:
    """A furniture surface: wood, or painted/laminate panels with noise and scratches."""
    base = pick_colour(rng, FURNITURE_COLOURS) if base is None else np.asarray(base, np.float32)
    if rng.uniform() < 0.4:
        return planks(h, w, rho, rng, base=base)
    lum = 0.7 * fbm(h, w, rng, 0.3 * rho, gain=0.72) - 0.3 * _stains(h, w, rng, 0.08 * rho, 0.15)
    return _colour(base, lum, 0.2, _chroma(h, w, rng, 0.5 * rho, 8.0))


def cloth(h: int, w: int, rho: float, rng: np.random.Generator, base=None, pattern: int | None = None,
          other=None) -> np.ndarray:
    """Clothing: a saturated colour with stripes, checks or blotches (in colour ``other``), plus a fine weave noise."""
    base = pick_colour(rng, CLOTH_COLOURS) if base is None else np.asarray(base, np.float32)
    if other is None:
        other = pick_colour(rng, CLOTH_COLOURS + [(240, 240, 240), (25, 25, 25)])
    other = np.asarray(other, np.float32)
    pattern = int(rng.integers(4)) if pattern is None else pattern
    if pattern == 1:  # horizontal stripes of random widths
        widths = rng.uniform(0.02, 0.09, int(h / (0.02 * rho)) + 2) * rho
        sel = (np.searchsorted(np.cumsum(widths), np.arange(h) + 0.5) % 2 == 1)[:, None] & np.ones((1, w), bool)
    elif pattern == 2:  # checks
        s = rng.uniform(0.04, 0.1) * rho
        vv, uu = np.arange(h)[:, None], np.arange(w)[None, :]
        sel = (np.floor(vv / s) + np.floor(uu / (s * rng.uniform(0.7, 1.4)))) % 2 == 1
    elif pattern == 3:  # blotches
        sel = _stains(h, w, rng, 0.12 * rho, 0.4) > 0
    else:
        sel = np.zeros((h, w), bool)
    lum = fbm(h, w, rng, 0.2 * rho, gain=0.75)
    img = np.where(sel[..., None], _colour(other, lum, 0.18), _colour(base, lum, 0.18))
    img += (12.0 * fbm(h, w, rng, 4.0, min_cell=1.0))[..., None]
    return img


def skin(h: int, w: int, rho: float, rng: np.random.Generator, tone=None) -> np.ndarray:
    tone = pick_colour(rng, SKIN_COLOURS) if tone is None else np.asarray(tone, np.float32)
    return _colour(tone, fbm(h, w, rng, 0.05 * rho, gain=0.7), 0.12)


def hair(h: int, w: int, rho: float, rng: np.random.Generator, colour=None) -> np.ndarray:
    colour = pick_colour(rng, HAIR_COLOURS) if colour is None else np.asarray(colour, np.float32)
    return _colour(colour, fbm(h, w, rng, 0.1 * rho, gain=0.8, aspect=0.3), 0.3) + 10.0


def stack_rows(parts: list[np.ndarray], splits: list[int]) -> np.ndarray:
    """Rows [0, s0) from parts[0], [s0, s1) from parts[1], …, the rest from the last part."""
    out = parts[-1].copy()
    lo = 0
    for part, hi in zip(parts[:-1], splits):
        out[lo:hi] = part[lo:hi]
        lo = hi
    return out
