"""The mapping losses of ADD-SLAM (Eq. 17-19, after MonoGS / 3DGS) and the image scores.

* colour: (1 − λ) ‖C − I‖₁ + λ (1 − SSIM(C, I)) over the mask, λ = 0.2 (3DGS Eq. 7's D-SSIM term);
* depth: ‖D − D*‖₁ over the mask, divided by the median target depth so that a monocular run's arbitrary
  scale does not change its weight;
* a scale regulariser: the isotropy term of MonoGS, Σᵢ ‖sᵢ − s̄ᵢ 1‖₁ on the log-scales (s̄ᵢ their mean),
  which keeps the Gaussians from growing into needles that look right only from the training views.

SSIM (Wang et al. 2004) with an 11 × 11 Gaussian window (σ = 1.5), C₁ = 0.01², C₂ = 0.03²; PSNR = 10 log₁₀ (1 / MSE)
for images in [0, 1].
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

C1, C2 = 0.01 ** 2, 0.03 ** 2


def _window(dtype) -> torch.Tensor:
    x = torch.arange(11, dtype=dtype) - 5
    g = torch.exp(-x * x / (2 * 1.5 ** 2))
    return g / g.sum()


def ssim_map(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Per-pixel SSIM of (H, W, 3) images, averaged over the channels: (H, W)."""
    g = _window(a.dtype)
    x = torch.stack([a, b, a * a, b * b, a * b]).permute(0, 3, 1, 2).reshape(15, 1, *a.shape[:2])

    def blur(t):
        t = F.conv2d(F.pad(t, (5, 5, 0, 0), mode="replicate"), g.view(1, 1, 1, 11))
        return F.conv2d(F.pad(t, (0, 0, 5, 5), mode="replicate"), g.view(1, 1, 11, 1))

    mu_a, mu_b, aa, bb, ab = blur(x).reshape(5, 3, *a.shape[:2])
    var_a, var_b, cov = aa - mu_a ** 2, bb - mu_b ** 2, ab - mu_a * mu_b
    s = ((2 * mu_a * mu_b + C1) * (2 * cov + C2)) / ((mu_a ** 2 + mu_b ** 2 + C1) * (var_a + var_b + C2))
    return s.mean(0)


def masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    m = mask.to(x.dtype)
    while m.dim() < x.dim():
        m = m[..., None]
    m = m.expand_as(x)
    return (x * m).sum() / m.sum().clamp_min(1.0)


def colour_loss(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, ssim_weight: float) -> torch.Tensor:
    l1 = masked_mean((render - target).abs(), mask)
    if ssim_weight <= 0:
        return l1
    return (1 - ssim_weight) * l1 + ssim_weight * (1 - masked_mean(ssim_map(render, target), mask))


def depth_loss(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor, scale: float) -> torch.Tensor:
    return masked_mean((render - target).abs(), mask) / scale


def isotropy(log_scales: torch.Tensor) -> torch.Tensor:
    if len(log_scales) == 0:
        return log_scales.sum()
    return (log_scales - log_scales.mean(1, keepdim=True)).abs().mean()


def psnr(a, b, mask=None) -> float:
    """PSNR in dB over the mask (all pixels when None); NaN when the mask is empty."""
    a, b = torch.as_tensor(a, dtype=torch.float64), torch.as_tensor(b, dtype=torch.float64)
    if mask is None:
        mask = torch.ones(a.shape[:2], dtype=torch.bool)
    mask = torch.as_tensor(mask, dtype=torch.bool)
    if not bool(mask.any()):
        return float("nan")
    mse = float(((a - b) ** 2)[mask].mean())
    return 10 * math.log10(1.0 / max(mse, 1e-12))


def ssim(a, b, mask=None) -> float:
    """Mean SSIM over the mask (all pixels when None); NaN when the mask is empty."""
    a, b = torch.as_tensor(a, dtype=torch.float32), torch.as_tensor(b, dtype=torch.float32)
    s = ssim_map(a, b)
    if mask is None:
        return float(s.mean())
    mask = torch.as_tensor(mask, dtype=torch.bool)
    return float(s[mask].mean()) if bool(mask.any()) else float("nan")
