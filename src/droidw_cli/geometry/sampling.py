"""Bilinear sampling on the BA grid, written out so that its weights are explicit.

Pixel (u, v) of an H × W map sits at x = u, y = v.  A point (x, y) is first
clamped to the image ([0, W − 1] × [0, H − 1], i.e. border padding), then

    x0 = min(⌊x⌋, W − 2),  ax = x − x0,   (same for y)
    f(x, y) = (1−ax)(1−ay) f[y0, x0] + ax (1−ay) f[y0, x0+1]
            + (1−ax) ay f[y0+1, x0] + ax ay f[y0+1, x0+1].

The four corner indices and weights are returned so that callers can also
scatter gradients back (∂f(x, y)/∂f[corner] = weight).  H and W must be ≥ 2.
"""

from __future__ import annotations

import torch
from torch import Tensor


def inside_image(x: Tensor, y: Tensor, h: int, w: int) -> Tensor:
    """True where (x, y) lies in [0, W − 1] × [0, H − 1]."""
    return (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)


def bilinear_corners(x: Tensor, y: Tensor, h: int, w: int, dim: int = 0) -> tuple[Tensor, Tensor]:
    """Flat corner indices ``y·W + x`` (4, ...) long and weights (4, ...) (sum 1).

    Corner order: (x0, y0), (x0+1, y0), (x0, y0+1), (x0+1, y0+1), stacked along
    ``dim`` (``dim=-1`` gives (..., 4), one row of four corners per point).
    """
    if h < 2 or w < 2:
        raise ValueError(f"bilinear sampling needs a grid of at least 2 × 2, got {h} × {w}")
    xc = x.clamp(0.0, float(w - 1))
    yc = y.clamp(0.0, float(h - 1))
    x0 = xc.floor().clamp(max=w - 2)
    y0 = yc.floor().clamp(max=h - 2)
    ax, ay = xc - x0, yc - y0
    bx, by = 1.0 - ax, 1.0 - ay
    base = y0.long() * w + x0.long()
    idx = torch.stack((base, base + 1, base + w, base + w + 1), dim=dim)
    wts = torch.stack((bx * by, ax * by, bx * ay, ax * ay), dim=dim)
    return idx, wts


def sample_maps(maps: Tensor, frame: Tensor, x: Tensor, y: Tensor) -> Tensor:
    """Bilinear samples of scalar maps (N, H, W) at (x, y) (E, P) in frames ``frame`` (E,).

    Returns (E, P), same dtype as ``maps``.
    """
    n, h, w = maps.shape
    idx, wts = bilinear_corners(x, y, h, w)
    flat = maps.reshape(n * h * w)
    offset = (frame * (h * w)).view(1, -1, 1)
    return (flat[idx + offset] * wts).sum(0)
