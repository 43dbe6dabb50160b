"""Dynamic masks of keyframes by scene consistency: warp → inconsistency → region growing.

For keyframe k the sources are its neighbours k − radius … k + radius
(excluding k, clipped to the sequence).  The pipeline is

    predict_views (warp.py) → inconsistency (consistency.py) → refine_mask (refine.py)

and the result is the union of the grown objects.  :func:`detect_dynamic`
uses ``DynamicsConfig.tau_scale``; scheduling (ADD-SLAM runs it every 5-10
frames) is the caller's.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import Tensor

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics.consistency import InconsistencyMaps, inconsistency
from droidw_cli.dynamics.params import DetectionParams
from droidw_cli.dynamics.refine import Objects, refine_mask
from droidw_cli.dynamics.warp import predict_views


@dataclass(frozen=True)
class FrameDetection:
    """Everything computed for one keyframe: the sources used, the error maps and the objects."""

    target: int
    sources: tuple[int, ...]
    maps: InconsistencyMaps
    objects: Objects

    @property
    def mask(self) -> Tensor:
        return self.objects.mask


def neighbour_sources(k: int, n: int, radius: int) -> tuple[int, ...]:
    """Indices k − radius … k + radius except k, inside [0, n)."""
    return tuple(j for j in range(k - radius, k + radius + 1) if j != k and 0 <= j < n)


def detect_frame(images: Tensor, disps: Tensor, poses_w2c: Tensor, intrinsics: Tensor, target: int,
                 sources: Sequence[int], tau_scale: float = 20.0,
                 params: DetectionParams | None = None) -> FrameDetection:
    """Run warp, inconsistency and refinement for one keyframe against ``sources``."""
    params = params or DetectionParams()
    pred_rgb, pred_disp, valid = predict_views(images, disps, poses_w2c, intrinsics, target, sources,
                                               min_depth=params.min_depth, depth_mode=params.depth_mode)
    disp = disps[target]
    maps = inconsistency(images[target], disp, pred_rgb, pred_disp, valid, tau_scale, params)
    depth = torch.where(disp > 0, 1.0 / torch.where(disp > 0, disp, torch.ones_like(disp)), torch.zeros_like(disp))
    objects = refine_mask(maps.m_dyn, images[target].to(disp.dtype), depth, params,
                          focal=(float(intrinsics[0]), float(intrinsics[1])))
    return FrameDetection(target, tuple(int(s) for s in sources), maps, objects)


def _as_tensor(x, dtype=None) -> Tensor:
    t = x if isinstance(x, Tensor) else torch.as_tensor(x)
    return t.to(dtype) if dtype is not None else t


def detect_dynamic(images, disps, poses_w2c, intrinsics, cfg: DynamicsConfig | None = None, radius: int = 2,
                   params: DetectionParams | None = None) -> Tensor:
    """Dynamic masks (K, h, w) bool of every keyframe, each compared with ≤ ``radius`` neighbours per side.

    ``images`` (K, h, w, 3) in [0, 1], ``disps`` (K, h, w) inverse depth, ``poses_w2c`` (K, 7),
    ``intrinsics`` (4,) for this grid (numpy arrays are accepted).  A sequence of one keyframe
    has no neighbours and gets an all-False mask.
    """
    cfg = cfg or DynamicsConfig()
    if radius < 1:
        raise ValueError(f"radius must be >= 1, got {radius}")
    disps = _as_tensor(disps)
    if not disps.is_floating_point():
        raise ValueError("disps must be a floating-point array")
    images = _as_tensor(images, disps.dtype)
    poses_w2c = _as_tensor(poses_w2c, disps.dtype)
    intrinsics = _as_tensor(intrinsics, disps.dtype)
    if disps.dim() != 3:
        raise ValueError(f"disps must be (K, h, w), got {tuple(disps.shape)}")
    n = disps.shape[0]
    masks = torch.zeros(disps.shape, dtype=torch.bool, device=disps.device)
    for k in range(n):
        sources = neighbour_sources(k, n, radius)
        if sources:
            masks[k] = detect_frame(images, disps, poses_w2c, intrinsics, k, sources, cfg.tau_scale, params).mask
    return masks
