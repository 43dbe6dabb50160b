"""The sensor depth on the BA grid, and a new keyframe's starting disparity (RGB-D mode)."""

from __future__ import annotations

import numpy as np
import torch


def grid_disparity(depth: np.ndarray, grid: tuple[int, int], min_depth: float = 0.1) -> torch.Tensor:
    """A working-size depth map (metres, 0 = invalid) as disparity on the 1/8 grid, (h, w) float32.

    Grid cell (u, v) is centred on working pixel (8u + 3.5, 8v + 3.5) (the
    intrinsics' pixel-centre convention, :func:`~droidw_cli.geometry.camera.scale_intrinsics`),
    so its disparity is the mean of 1/D over the four pixels around that centre,

        D̄(u, v) = ¼ Σ_{a, b ∈ {3, 4}} 1 / D(8u + a, 8v + b),

    exact where disparity is affine in the image (any plane), and 0 unless all
    four are valid (D > ``min_depth``), so no depth is invented across holes.
    Taking the block's first pixel instead (OpenCV's INTER_NEAREST) reads the
    depth 3.5 px up and to the left: on a floor seen from 1.5 m that is a few
    per cent too far, a scale bias of the whole RGB-D reconstruction.
    """
    h, w = grid
    d = np.asarray(depth, dtype=np.float32)
    quad = np.stack([d[a : a + 8 * h : 8, b : b + 8 * w : 8] for a in (3, 4) for b in (3, 4)])
    valid = (quad > min_depth).all(axis=0)
    disp = np.where(valid, (1.0 / np.maximum(quad, min_depth)).mean(axis=0), 0.0)
    return torch.from_numpy(disp.astype(np.float32))


def seed_disparity(fallback: torch.Tensor | float, prior: torch.Tensor | None, hw: tuple[int, int],
                   device: torch.device | str = "cpu") -> torch.Tensor:
    """Initial disparity of a keyframe: the sensor's where it has one, ``fallback`` elsewhere.

    With a depth prior D (disparity, 0 = invalid) the seed is

        d₀(p) = D(p)          where D(p) > 0,
        d₀(p) = fallback(p)   otherwise,

    ``fallback`` being the transferred disparity (or a constant).  Without a
    prior d₀ = fallback.  This matters for the scale: the BA's gauge is fixed
    by the first keyframe (t0 = 1) during initialisation and by two fixed
    keyframes in every later window, so the metric scale has to be present in
    the disparities *before* the first iterations; the weak prior term
    γ_d (d − D)² alone cannot pull a whole mis-scaled reconstruction along the
    (LM-damped) scale direction, and two fixed poses then freeze the wrong scale.
    """
    base = torch.as_tensor(fallback, dtype=torch.float32, device=device).expand(*hw)
    if prior is None:
        return base.clone()
    prior = prior.to(device=device, dtype=torch.float32).reshape(*hw)
    return torch.where(prior > 0, prior, base)
