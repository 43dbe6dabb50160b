"""Frame distance and disparity transfer between keyframes, on the 1/8 grid.

Frame distance (DROID-SLAM's keyframe and proximity criterion).  For a
keyframe pair (i, j) with relative pose G_ij = G_j G_i⁻¹ = (R_ij, t_ij), the
induced flow of every grid pixel x of frame i with disparity d_i(x) is
p_ij(x) − x (Eq. 1).  With the translation-only pose (I, t_ij),

    d_full(i, j)  = mean_x ‖p_ij(x) − x‖
    d_trans(i, j) = mean_x ‖p_ij^(I, t)(x) − x‖
    d(i, j)       = β d_full + (1 − β) d_trans,     β = 0.75,

averaged over the valid pixels, and symmetrised as ½ (d(i, j) + d(j, i)).
Rotation about the optical centre moves pixels without parallax; the
translation-only term keeps a rotating camera from looking like a moving
one.  Everything is in grid pixels, the unit of every flow threshold.

Disparity transfer: a new keyframe starts from its predecessor's disparity
forward-warped through the current poses (nearest surface wins), not from a
constant; cells nothing lands on take the median of what landed.
"""

from __future__ import annotations

import torch
from torch import Tensor

from droidw_cli.geometry.lie import pose_compose, pose_inverse
from droidw_cli.geometry.poses import log_departure, retract
from droidw_cli.geometry.projection import pixel_grid, project_edges

#: pairs whose reprojection is valid on fewer pixels than this count as infinitely far apart
MIN_VALID = 0.5


def _mean_flow(rel: Tensor, disps: Tensor, intrinsics: Tensor, min_depth: float) -> Tensor:
    """Mean induced flow (E,) of disps (E, h, w) under relative poses rel (E, 7) (frame 2e → 2e+1)."""
    e, h, w = disps.shape
    ident = torch.zeros_like(rel)
    ident[:, 6] = 1.0
    poses = torch.stack([ident, rel], 1).reshape(2 * e, 7)
    d2 = disps.repeat_interleave(2, 0)
    ii = torch.arange(0, 2 * e, 2, device=disps.device)
    proj = project_edges(poses, d2, intrinsics, ii, ii + 1, min_depth)
    gx, gy = pixel_grid(h, w, disps.device, disps.dtype)
    mag = torch.hypot(proj.coords[:, 0] - gx, proj.coords[:, 1] - gy)
    valid = proj.valid.float()
    mean = (mag * valid).sum(1) / valid.sum(1).clamp(min=1.0)
    return torch.where(valid.mean(1) >= MIN_VALID, mean, torch.full_like(mean, float("inf")))


def frame_distance(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
                   beta: float = 0.75, min_depth: float = 0.05, bidirectional: bool = True,
                   stride: int = 1) -> Tensor:
    """d(i, j) in grid px for every pair (module docstring); poses (N, 7) world-to-camera, disps (N, h, w).

    ``stride`` s > 1 averages over every s-th grid pixel only (s² times cheaper):
    the pixel s·x' of the grid is the pixel x' of a grid with intrinsics K/s, so
    the sub-grid's flow times s is the grid's flow at those pixels.
    """
    if ii.numel() == 0:
        return torch.zeros(0, dtype=disps.dtype, device=disps.device)
    if stride > 1:
        sub = disps[:, ::stride, ::stride]
        return stride * frame_distance(poses, sub, intrinsics / stride, ii, jj, beta, min_depth, bidirectional)

    def one_way(a: Tensor, b: Tensor) -> Tensor:
        rel = pose_compose(poses[b], pose_inverse(poses[a]))
        trans = rel.clone()
        trans[:, 3:6] = 0.0
        trans[:, 6] = 1.0
        both = _mean_flow(torch.cat([rel, trans]), disps[a].repeat(2, 1, 1), intrinsics, min_depth)
        full, tonly = both[: a.numel()], both[a.numel():]
        return beta * full + (1.0 - beta) * tonly

    d = one_way(ii, jj)
    return 0.5 * (d + one_way(jj, ii)) if bidirectional else d


def candidate_distance(prev: Tensor, last: Tensor, disp: Tensor, intrinsics: Tensor, alpha: float, full: float,
                       beta: float, min_depth: float = 0.05, stride: int = 1) -> float:
    """Predicted d(k − 1, c) of a keyframe candidate c before any of its flow or BA (``frontend.skip_doomed``).

    Keyframe removal drops the second-newest keyframe when d(k − 2, k − 1) < ``keyframe_thresh``; under
    fast rotation it dropped about every other candidate after paying for its flow and window BA (rotate:
    168 keyframes added, 82 removed).  The full-motion part is ``full``, the motion filter's mean flow (grid
    px) from the newest keyframe; the translation-only part is that of the newest keyframe's disparity
    ``disp`` (h, w) under its pose ``last`` carried on at constant velocity from ``prev`` (world-to-camera,
    (7,)), ``alpha`` = (c − f_{k−1}) / (f_{k−1} − f_{k−2}) in frame time:

        G_c = Exp(α Log(G_{k−1} G_{k−2}⁻¹)) G_{k−1},   d̂ = β · full + (1 − β) · d_trans(k − 1, c)   (one way).
    """
    pose = retract(alpha * log_departure(last, prev), last)
    idx = torch.zeros(1, dtype=torch.long, device=disp.device)
    trans = frame_distance(torch.stack([last, pose]), disp[None].expand(2, -1, -1), intrinsics, idx, idx + 1, 0.0,
                           min_depth, bidirectional=False, stride=stride)
    return beta * full + (1.0 - beta) * float(trans[0])


def transfer_disparity(pose_src: Tensor, disp_src: Tensor, pose_dst: Tensor, intrinsics: Tensor,
                       min_depth: float = 0.05) -> Tensor:
    """disp_src (h, w) forward-warped into the camera ``pose_dst`` (nearest surface wins)."""
    h, w = disp_src.shape
    poses = torch.stack([pose_src, pose_dst])
    idx0 = torch.zeros(1, dtype=torch.long, device=disp_src.device)
    idx1 = torch.ones(1, dtype=torch.long, device=disp_src.device)
    proj = project_edges(poses, torch.stack([disp_src, disp_src]), intrinsics, idx0, idx1, min_depth)
    x, y = proj.coords[0, 0].round().long(), proj.coords[0, 1].round().long()
    new_disp = proj.disp[0] * proj.z[0]  # (P, d) lands at depth Z/d in the new frame
    ok = proj.valid[0] & (x >= 0) & (x < w) & (y >= 0) & (y < h)
    out = torch.full((h * w,), -1.0, dtype=disp_src.dtype, device=disp_src.device)
    out.scatter_reduce_(0, (y * w + x)[ok], new_disp[ok], reduce="amax")
    hit = out > 0
    fill = out[hit].median() if bool(hit.any()) else disp_src.median()
    return torch.where(hit, out, fill).reshape(h, w)
