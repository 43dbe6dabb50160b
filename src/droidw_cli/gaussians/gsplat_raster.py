"""gsplat's CUDA rasteriser behind the :class:`~droidw_cli.gaussians.raster.Rasteriser` interface.

Only where a CUDA device and the ``gsplat`` package (Apache-2.0; it compiles its kernels on first use) exist;
``auto`` passes it over otherwise, with the reason.  gsplat samples pixel (u, v) at (u + ½, v + ½), so the
principal point is shifted by +½ to keep droidw's integer pixel centres.  Its ``RGB+D`` mode returns the same
accumulated depth Σ zᵢ wᵢ as the torch rasteriser.  Not exercised by the CPU test suite.
"""

from __future__ import annotations

import torch

from droidw_cli.gaussians.raster import Rasteriser, RenderOutput


class GsplatRasteriser(Rasteriser):
    name = "gsplat"

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        if not torch.cuda.is_available():
            return False, "no CUDA device"
        try:
            import gsplat  # noqa: F401
        except ImportError:
            return False, "the gsplat package is not installed (pip install gsplat)"
        return True, "CUDA"

    def render(self, g, cam, background=(0.0, 0.0, 0.0)) -> RenderOutput:
        from gsplat import rasterization

        dev = torch.device("cuda")
        dtype = g.means.dtype
        fx, fy, cx, cy = cam.intrinsics
        k = torch.tensor([[fx, 0.0, cx + 0.5], [0.0, fy, cy + 0.5], [0.0, 0.0, 1.0]], device=dev)
        h, w = cam.size
        move = (lambda v: v.to(dev, torch.float32))
        colours, alphas, meta = rasterization(
            move(g.means), move(g.quats), torch.exp(move(g.log_scales)), torch.sigmoid(move(g.opacity_logits)),
            torch.clamp_min(0.5 + 0.28209479177387814 * move(g.dc), 0.0), move(cam.w2c)[None], k[None], w, h,
            eps2d=0.3, render_mode="RGB+D", backgrounds=None, packed=False)
        out = colours[0]
        alpha = alphas[0, ..., 0]
        rgb = out[..., :3] + (1 - alpha)[..., None] * torch.as_tensor(background, device=dev, dtype=torch.float32)
        radii = meta.get("radii")
        radius = radii[0].reshape(len(g), -1).max(-1).values if radii is not None else torch.zeros(len(g))
        back = (lambda v: v.to(g.means.device, dtype))
        return RenderOutput(back(rgb), back(out[..., 3]), back(alpha), -1, radius.to(g.means.device).long())
