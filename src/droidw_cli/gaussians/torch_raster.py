"""The pure-torch CPU rasteriser: EWA splatting and front-to-back alpha compositing over pixel-Gaussian pairs.

For each Gaussian (3DGS, Kerbl et al. 2023, Sec. 4 and 6; Zwicker et al. 2001, EWA splatting):

* camera-frame mean X = W μ + t (W, t: the world-to-camera rotation and translation), depth z = X_z;
* image mean μ' = (f_x X_x / z + c_x, f_y X_y / z + c_y);
* image covariance Σ' = J W Σ Wᵀ Jᵀ + 0.3 I (3DGS Eq. 5 with its low-pass dilation), J the Jacobian of the
  projection at X, J = [[f_x / z, 0, −f_x X_x / z²], [0, f_y / z, −f_y X_y / z²]] (X_x / z and X_y / z clamped
  to 1.3 × the field of view, as 3DGS does, so that Gaussians far outside the image stay bounded);
* a footprint radius r = ⌈3 √λ_max(Σ')⌉ pixels (capped by ``max_radius``).

A Gaussian *touches* the pixels p (integer centres) with ‖p − μ'‖_∞ ≤ r; at such a pixel its alpha is
αᵢ(p) = min(0.99, oᵢ exp(−½ (p − μ')ᵀ Σ'⁻¹ (p − μ'))), and a pair with αᵢ(p) < 1/255 is dropped.  Gaussians
with z < ``near`` are culled.  Each pixel composites its pairs front to back, sorted by the depth of the
Gaussians' centres (3DGS Eq. 3):

    C(p) = Σᵢ cᵢ αᵢ Tᵢ,   Tᵢ = Πⱼ<ᵢ (1 − αⱼ),   D(p) = Σᵢ zᵢ αᵢ Tᵢ,   A(p) = Σᵢ αᵢ Tᵢ,

and the background fills C(p) + (1 − A(p)) b.

Vectorisation: every pair (Gaussian, pixel of its footprint) is one row of flat tensors, made with
``repeat_interleave`` (no Python loop over pixels or Gaussians).  The rows are sorted by the key
pixel · N + depth rank, so that each pixel's rows form one contiguous, depth-ordered segment.  The
transmittance is an exclusive segmented cumulative sum of log(1 − α) (a global float64 cumulative sum minus
its value at the segment's start), and the sums over a pixel are ``index_add``.  Everything after the
(integer, non-differentiable) pair list is differentiable by autograd; on the CPU every step is
deterministic (unique sort keys, sequential ``index_add``).
"""

from __future__ import annotations

import torch

from droidw_cli.gaussians.camera import Camera
from droidw_cli.gaussians.model import Gaussians, dc_to_rgb, quat_to_rotmat
from droidw_cli.gaussians.raster import Rasteriser, RenderOutput

ALPHA_MIN = 1.0 / 255.0
ALPHA_MAX = 0.99
LOW_PASS = 0.3


def project(g: Gaussians, cam: Camera, near: float):
    """Per Gaussian: image mean (N, 2), conic (N, 3) = the entries a, b, c of Σ'⁻¹ = [[a, b], [b, c]],
    depth z (N,), radius (N,) int64 (0 = culled)."""
    dtype = g.means.dtype
    w2c = cam.w2c.to(dtype)
    rot, trans = w2c[:3, :3], w2c[:3, 3]
    fx, fy, cx, cy = cam.intrinsics
    h, w = cam.size
    xc = g.means @ rot.T + trans
    z = xc[:, 2]
    zs = z.clamp_min(near)
    lim_x = 1.3 * max(cx + 0.5, w - 0.5 - cx) / fx
    lim_y = 1.3 * max(cy + 0.5, h - 0.5 - cy) / fy
    tx = (xc[:, 0] / zs).clamp(-lim_x, lim_x)
    ty = (xc[:, 1] / zs).clamp(-lim_y, lim_y)
    mean2d = torch.stack([fx * xc[:, 0] / zs + cx, fy * xc[:, 1] / zs + cy], dim=-1)
    zero = torch.zeros_like(z)
    jac = torch.stack([torch.stack([fx / zs, zero, -fx * tx / zs], -1),
                       torch.stack([zero, fy / zs, -fy * ty / zs], -1)], dim=1)  # (N, 2, 3)
    m = jac @ rot  # J W
    scaled = quat_to_rotmat(g.quats) * torch.exp(g.log_scales)[:, None, :]  # R S
    ms = m @ scaled  # J W R S, so Σ' = (J W R S)(J W R S)ᵀ
    cov = ms @ ms.transpose(1, 2)
    a = cov[:, 0, 0] + LOW_PASS
    b = cov[:, 0, 1]
    c = cov[:, 1, 1] + LOW_PASS
    det = (a * c - b * b).clamp_min(1e-12)
    conic = torch.stack([c / det, -b / det, a / det], dim=-1)
    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam = mid + torch.sqrt((mid * mid - det).clamp_min(0.0))
        radius = torch.ceil(3.0 * torch.sqrt(lam)).to(torch.int64)
        radius = torch.where(z > near, radius, torch.zeros_like(radius))
    return mean2d, conic, z, radius


def pair_list(mean2d: torch.Tensor, radius: torch.Tensor, size: tuple[int, int], max_radius: int):
    """Every (Gaussian, pixel) pair of the footprints ‖p − μ'‖_∞ ≤ r, clipped to the image.

    Returns (gaussian index, pixel x, pixel y), int64 rows."""
    h, w = size
    with torch.no_grad():
        r = radius.clamp(max=max_radius)
        mx, my = mean2d[:, 0].detach(), mean2d[:, 1].detach()
        x0 = torch.ceil(mx - r).clamp(min=0).to(torch.int64)
        x1 = torch.floor(mx + r).clamp(max=w - 1).to(torch.int64)
        y0 = torch.ceil(my - r).clamp(min=0).to(torch.int64)
        y1 = torch.floor(my + r).clamp(max=h - 1).to(torch.int64)
        bw = (x1 - x0 + 1).clamp_min(0)
        bh = (y1 - y0 + 1).clamp_min(0)
        bw = torch.where(r > 0, bw, torch.zeros_like(bw))
        counts = bw * bh
        gid = torch.repeat_interleave(torch.arange(len(counts)), counts)
        starts = torch.cumsum(counts, 0) - counts
        local = torch.arange(len(gid)) - starts[gid]
        bwg = bw[gid]
        px = x0[gid] + local % bwg.clamp_min(1)
        py = y0[gid] + local // bwg.clamp_min(1)
    return gid, px, py


class TorchRasteriser(Rasteriser):
    """The CPU reference: pure torch, differentiable by autograd (module docstring for the maths)."""

    name = "torch"

    def __init__(self, near: float = 1e-3, max_radius: int = 256) -> None:
        self.near = near
        self.max_radius = max_radius

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        return True, "pure torch, any device"

    def render(self, g: Gaussians, cam: Camera, background=(0.0, 0.0, 0.0)) -> RenderOutput:
        h, w = cam.size
        dtype = g.means.dtype
        n_pix = h * w
        bg = torch.as_tensor(background, dtype=dtype)
        if len(g) == 0:
            return RenderOutput(bg.expand(h, w, 3).clone(), torch.zeros(h, w, dtype=dtype),
                                torch.zeros(h, w, dtype=dtype), 0, torch.zeros(0, dtype=torch.int64))
        mean2d, conic, z, radius = project(g, cam, self.near)
        gid, px, py = pair_list(mean2d, radius, cam.size, self.max_radius)
        opacity = torch.sigmoid(g.opacity_logits)
        # one gather of every per-Gaussian quantity a pair needs: μ'ₓ, μ'ᵧ, the conic a b c, o, z, r g b
        packed = torch.cat([mean2d, conic, opacity[:, None], z[:, None], dc_to_rgb(g.dc)], dim=1)
        with torch.no_grad():  # drop the pairs below 1/255 before sorting (their alpha would be 0)
            keep = _alpha(packed.detach().index_select(0, gid).unbind(1), px, py) >= ALPHA_MIN
            gid, px, py = gid[keep], px[keep], py[keep]
            rank = torch.empty_like(z, dtype=torch.int64)
            rank[torch.argsort(z.detach(), stable=True)] = torch.arange(len(z))
            pix = py * w + px
            order = torch.argsort(pix * len(z) + rank.index_select(0, gid))
            gid, px, py, pix = gid[order], px[order], py[order], pix[order]
            _, counts = torch.unique_consecutive(pix, return_counts=True)
            seg_start = torch.repeat_interleave(torch.cumsum(counts, 0) - counts, counts)
        cols = packed.index_select(0, gid).unbind(1)  # unbind, not slices: its backward is one stack
        alpha = torch.clamp_max(_alpha(cols, px, py), ALPHA_MAX)
        log_t = torch.log1p(-alpha).double()
        excl = torch.cumsum(log_t, 0) - log_t  # Σ_{j<i} log(1 − αⱼ) over every earlier row
        trans = torch.exp((excl - excl.index_select(0, seg_start)).to(dtype))  # … within the pixel's segment
        weight = alpha * trans
        # colour, depth and opacity summed per pixel in one index_add: rows [w r, w g, w b, w z, w]
        sums = torch.zeros(n_pix, 5, dtype=dtype).index_add(
            0, pix, torch.stack([weight * cols[7], weight * cols[8], weight * cols[9], weight * cols[6], weight], 1))
        colour, depth, acc = sums[:, :3], sums[:, 3], sums[:, 4]
        colour = colour + (1.0 - acc)[:, None] * bg
        return RenderOutput(colour.reshape(h, w, 3), depth.reshape(h, w), acc.reshape(h, w), int(len(gid)),
                            radius)


def _alpha(cols, px: torch.Tensor, py: torch.Tensor) -> torch.Tensor:
    """o exp(−½ dᵀ Σ'⁻¹ d) for the packed pair columns μ'ₓ, μ'ᵧ, a, b, c, o, … (d = p − μ')."""
    mx, my, a, b, c, o = cols[:6]
    dx = px.to(mx.dtype) - mx
    dy = py.to(mx.dtype) - my
    power = (-0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy).clamp_max(0.0)
    return o * torch.exp(power)


def footprint_pixels(radius: torch.Tensor) -> int:
    """The pairs the footprints hold before clipping and the 1/255 cut (a cost estimate)."""
    return int(((2 * radius + 1) ** 2 * (radius > 0)).sum())


__all__ = ["TorchRasteriser", "project", "pair_list", "footprint_pixels", "ALPHA_MIN", "ALPHA_MAX", "LOW_PASS"]
