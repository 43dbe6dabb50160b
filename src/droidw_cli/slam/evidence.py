"""Per-pixel evidence channels for the uncertainty map (droidw's extension).

DROID-W's affine map u = softplus(θ·F + b) reads only the appearance
features F.  XFeat features are low-level, so an affine map of them alone
separates movers poorly (AUROC about 0.8 on our synthetic scenes even with
exact geometry).  Two cheap multi-view cues, appended as extra inputs X of
the same affine map (u = softplus(θ·[F; X] + b)), lift that to about 0.95:

* ``log(1 + r̄)``: the mean over a keyframe's outgoing edges with
  |i − j| ≥ 2 of the flow residual r = ‖p*_ij − p_ij‖ (grid pixels) under the
  current poses and depths: movers land somewhere else than the rigid scene
  predicts.  Adjacent pairs are left out because a pixel's free disparity can
  absorb a mover's motion along the epipolar line of one pair, not of several;
* ``1 − w̄``: one minus the mean correspondence confidence (forward-backward
  and photometric agreement), low where pixels are occluded or disoccluded.

θ still learns from the DROID-W objective (Eq. 6-9) how much to trust each
channel; nothing here is hand-weighted.
"""

from __future__ import annotations

import torch
from torch import Tensor

from droidw_cli.ba.interface import BABackend
from droidw_cli.ba.types import BAState, EdgeSet

EVIDENCE_CHANNELS = 2
#: the residual channel uses edges at least this many keyframes apart
WIDE_GAP = 2


def evidence_maps(backend: BABackend, state: BAState, edges: EdgeSet, min_depth: float) -> Tensor:
    """(N, 2, H, W) evidence of every frame from its outgoing edges (0 where it has none)."""
    n = state.num_frames
    h, w = state.grid
    coords, valid = backend.reproject(state, edges.ii, edges.jj, min_depth)
    v = valid.float() * ((edges.ii - edges.jj).abs() >= WIDE_GAP).float()[:, None, None]
    r = torch.linalg.vector_norm(edges.target - coords, dim=-1) * v
    count = torch.zeros(n, h, w).index_add_(0, edges.ii, v).clamp_min(1.0)
    residual = torch.log1p(torch.zeros(n, h, w).index_add_(0, edges.ii, r) / count)
    edges_per_pixel = torch.zeros(n, h, w).index_add_(0, edges.ii, torch.ones_like(v)).clamp_min(1.0)
    confidence = torch.zeros(n, h, w).index_add_(0, edges.ii, edges.weight[..., 0]) / edges_per_pixel
    has_edges = torch.zeros(n).index_add_(0, edges.ii, torch.ones(edges.num_edges)) > 0
    doubt = torch.where(has_edges[:, None, None], 1.0 - confidence, torch.zeros_like(confidence))
    return torch.stack([residual, doubt], 1)
