"""The static map (ADD-SLAM, "static map"): Gaussians from the keyframes' static pixels, poses fixed.

Keyframes are taken in time order.  Each one first *densifies* the map (always, whatever the time budget, so
that every keyframe is covered): the map is rendered at its pose and a
new Gaussian is put on every ``init_stride``-th pixel that is static (not in the dilated dynamic mask), has a
depth d, and whose rendered opacity is below ``densify_alpha`` (0.8), at X = T_wc · d K⁻¹ (u, v, 1)ᵀ, with the
pixel's colour, opacity ``init_opacity`` and a round standard deviation of ``init_sigma`` · stride pixels at
depth d (σ = init_sigma · stride · d / f).  Then the map takes its share of Adam steps, half of them on the new
keyframe and half on a random earlier one, paced so that a short budget thins the steps out evenly
(:class:`Pace`); a final ``refine_fraction`` of the steps go to random keyframes.
Each step renders one keyframe and minimises (``losses``)

    L = L_colour(static ∧ has depth) + w_d L_depth(static ∧ has depth) + w_s L_iso,

ADD-SLAM's mask being "not dynamic and valid depth".  Positions learn at ``lr_position`` × the median depth
(the scene's scale), decaying exponentially to ``lr_position_final`` ×; Gaussians whose opacity fell below
``prune_opacity`` are removed at the end.  Random choices come from one seeded generator, so on the CPU the
map is the same on every run that is not cut short by the time budget.
"""

from __future__ import annotations

import math
import time

import numpy as np
import torch
from tqdm import tqdm

from droidw_cli.gaussians.camera import Camera
from droidw_cli.gaussians.inputs import MapInputs, Views
from droidw_cli.gaussians.losses import colour_loss, depth_loss, isotropy
from droidw_cli.gaussians.model import Gaussians
from droidw_cli.gaussians.optim import GaussianAdam
from droidw_cli.gaussians.params import MapParams


class Deadline:
    """A wall-clock limit: ``over()`` once ``seconds`` have passed since ``start``."""

    def __init__(self, start: float, seconds: float) -> None:
        self.start, self.seconds = start, seconds

    def over(self) -> bool:
        return time.perf_counter() - self.start >= self.seconds


class Pace:
    """Spreads a budget over a loop: after a fraction ``done`` of the loop, at most ``done`` × ``share`` of the
    deadline's time should have passed (so that a short budget thins the steps out instead of leaving the
    last keyframes unmapped)."""

    def __init__(self, deadline: Deadline, share: float) -> None:
        self.deadline = deadline
        self.t0 = time.perf_counter()
        self.available = max(0.0, deadline.start + deadline.seconds - self.t0)
        self.share = share

    def behind(self, done: float) -> bool:
        return self.deadline.over() or time.perf_counter() - self.t0 > done * self.share * self.available


def camera(inputs: MapInputs, views: Views, j: int) -> Camera:
    return Camera.from_c2w(inputs.intrinsics, views.poses[j], inputs.size)


def backproject(inputs: MapInputs, views: Views, j: int, pick: np.ndarray, stride: int, sigma_px: float,
                opacity: float) -> Gaussians:
    """Gaussians on the pixels ``pick`` (H, W bool) of view j: world positions from its depth, colours from its image."""
    v, u = np.nonzero(pick)
    d = views.depth[j][v, u].astype(np.float64)
    fx, fy, cx, cy = inputs.intrinsics
    xc = np.stack([(u - cx) / fx * d, (v - cy) / fy * d, d], axis=1)
    c2w = views.poses[j]
    xw = xc @ c2w[:3, :3].T + c2w[:3, 3]
    rgb = torch.as_tensor(views.images[j][v, u], dtype=torch.float32)
    sigma = torch.as_tensor(sigma_px * stride * d / fx, dtype=torch.float32)
    return Gaussians.isotropic(torch.as_tensor(xw, dtype=torch.float32), rgb, sigma, opacity)


def stride_grid(size: tuple[int, int], stride: int) -> np.ndarray:
    grid = np.zeros(size, dtype=bool)
    o = stride // 2
    grid[o::stride, o::stride] = True
    return grid


class StaticMapper:
    """Fits the static map (module docstring); ``run`` returns the Gaussians and a summary dict."""

    def __init__(self, inputs: MapInputs, params: MapParams, rasteriser, deadline: Deadline, progress: bool) -> None:
        self.inputs, self.p, self.raster, self.deadline, self.progress = inputs, params, rasteriser, deadline, progress
        kf = inputs.keyframes
        self.mask = torch.as_tensor(kf.static & (kf.depth > 0))
        self.images = torch.as_tensor(kf.images)
        self.depth = torch.as_tensor(kf.depth)
        valid = kf.depth[kf.depth > 0]
        self.scene_depth = float(np.median(valid)) if valid.size else 1.0
        self.gen = torch.Generator().manual_seed(params.seed)
        self.steps_done = 0
        self.losses: list[float] = []

    def lr_position(self) -> float:
        p = self.p
        frac = min(1.0, self.steps_done / max(1, p.steps))
        return self.scene_depth * math.exp((1 - frac) * math.log(p.lr_position) + frac * math.log(p.lr_position_final))

    def densify(self, g: Gaussians | None, opt: GaussianAdam | None, j: int) -> tuple[Gaussians, GaussianAdam, int]:
        kf, p = self.inputs.keyframes, self.p
        pick = stride_grid(self.inputs.size, p.init_stride) & kf.static[j] & (kf.depth[j] > 0)
        if g is not None and len(g):
            with torch.no_grad():
                alpha = self.raster.render(g.detached(), camera(self.inputs, kf, j)).alpha.numpy()
            pick &= alpha < p.densify_alpha
        new = backproject(self.inputs, kf, j, pick, p.init_stride, p.init_sigma, p.init_opacity)
        if g is None:
            g = new
            opt = GaussianAdam(g, self.lrs())
        elif len(new):
            opt.append(new)
        return opt.g, opt, len(new)

    def lrs(self) -> dict[str, float]:
        p = self.p
        return {"means": self.lr_position(), "dc": p.lr_colour, "opacity_logits": p.lr_opacity,
                "log_scales": p.lr_scale, "quats": p.lr_rotation}

    def step(self, opt: GaussianAdam, j: int) -> float:
        p, kf = self.p, self.inputs.keyframes
        opt.lrs["means"] = self.lr_position()
        out = self.raster.render(opt.g, camera(self.inputs, kf, j))
        m = self.mask[j]
        loss = colour_loss(out.colour, self.images[j], m, p.ssim_weight)
        loss = loss + p.depth_weight * depth_loss(out.depth, self.depth[j], m, self.scene_depth)
        seen = out.radius > 0
        loss = loss + p.scale_weight * isotropy(opt.g.log_scales[seen]) * 1e-3
        loss.backward()
        opt.step()
        self.steps_done += 1
        return float(loss.detach())

    def run(self) -> tuple[Gaussians, dict]:
        p, k = self.p, len(self.inputs.keyframes)
        incremental = int(round(p.steps * (1 - p.refine_fraction)))
        per_kf = [incremental // k + (1 if j < incremental % k else 0) for j in range(k)]
        g, opt, added = None, None, 0
        ended = "steps"
        pace = Pace(self.deadline, 1 - p.refine_fraction)
        bar = tqdm(total=p.steps, desc="static map", unit="step", disable=not self.progress, dynamic_ncols=True)
        try:
            for j in range(k):  # every keyframe adds its Gaussians, even when the budget allows it no steps
                g, opt, n = self.densify(g, opt, j)
                added += n
                for s in range(per_kf[j]):
                    if pace.behind((j + 1) / k):
                        ended = "time budget"
                        break
                    pick = j if s % 2 == 0 else int(torch.randint(0, j + 1, (1,), generator=self.gen))
                    self.losses.append(self.step(opt, pick))
                    bar.update(1)
            while self.steps_done < p.steps:
                if self.deadline.over():
                    ended = "time budget"
                    break
                self.losses.append(self.step(opt, int(torch.randint(0, k, (1,), generator=self.gen))))
                bar.update(1)
        finally:
            bar.close()
        if opt is None:
            return Gaussians.empty(), {"steps": 0, "ended": ended, "added": 0, "pruned": 0}
        keep = torch.sigmoid(opt.g.opacity_logits.detach()) >= p.prune_opacity
        pruned = int((~keep).sum())
        opt.keep(keep)
        g = opt.g.detached()
        return g, {"steps": self.steps_done, "ended": ended, "added": added, "pruned": pruned,
                   "final_loss": self.losses[-1] if self.losses else None,
                   "scene_depth": self.scene_depth}
