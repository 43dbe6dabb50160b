"""Synthetic BA problems with exact ground truth (tests and ``benchmarks/ba_bench.py``).

The scene is the surface Z = z0 + A sin(kx X) cos(ky Y) (world frame, metres)
seen by a camera that slides along +X while swaying and yawing a little.  Each
keyframe's depth map is ray-cast against that one surface, so all frames see
the same world points.  Targets p*_ij come from the true poses and depths.

Static features are random Fourier features of the world point,
F(X) = normalise(cos(Ω X + φ)), so they agree across frames through the true
correspondence.  Optionally a rectangular "mover" covers part of the image in
some frames: its targets are shifted as if the object moved by
``mover_shift`` px per keyframe of separation, and its features are
normalise(fresh noise + β m) — new each frame (so they do not match across
frames) but with a common direction m that a linear map can learn.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from droidw_cli.ba.types import BAState, EdgeSet
from droidw_cli.geometry.lie import pose_compose, pose_distance, pose_inverse, pose_act, se3_exp
from droidw_cli.geometry.projection import pixel_grid, reproject

#: surface Z = SURF_Z0 + SURF_AMP sin(SURF_KX X) cos(SURF_KY Y)
SURF_Z0, SURF_AMP, SURF_KX, SURF_KY = 3.0, 0.8, 1.1, 0.9
#: fixed-point iterations of the ray cast (contraction < 0.6 for this surface and field of view)
RAY_ITERS = 40
#: spatial frequency scale (rad/m) of the static Fourier features
FEATURE_FREQ = 1.5


@dataclass(frozen=True)
class SyntheticProblem:
    """A BA problem: the true state, the edges (targets from the truth) and the mover mask (N, H, W)."""

    truth: BAState
    edges: EdgeSet
    mover_mask: Tensor


def camera_path(num_frames: int, step: float = 0.06) -> Tensor:
    """World-to-camera poses (N, 7): slide along +X, sway in Y/Z, yaw and pitch a few degrees."""
    t = torch.arange(num_frames, dtype=torch.float64)
    pos = torch.stack((step * t, 0.05 * torch.sin(0.7 * t), 0.08 * torch.sin(0.3 * t)), dim=1)
    rotvec = torch.stack((0.03 * torch.sin(0.5 * t), 0.05 * torch.sin(0.4 * t), 0.02 * torch.cos(0.6 * t)), dim=1)
    cam_to_world = se3_exp(torch.cat((torch.zeros_like(pos), rotvec), dim=1))
    cam_to_world = torch.cat((pos, cam_to_world[:, 3:]), dim=1)
    return pose_inverse(cam_to_world)


def _surface_z(x: Tensor, y: Tensor) -> Tensor:
    return SURF_Z0 + SURF_AMP * torch.sin(SURF_KX * x) * torch.cos(SURF_KY * y)


def ray_cast_depth(poses: Tensor, intrinsics: Tensor, h: int, w: int) -> tuple[Tensor, Tensor]:
    """(depth (N, H, W), world points (N, HW, 3)) of the surface seen from poses (N, 7), float64."""
    fx, fy, cx, cy = intrinsics.double().unbind()
    gx, gy = pixel_grid(h, w, dtype=torch.float64)
    rays_c = torch.stack(((gx - cx) / fx, (gy - cy) / fy, torch.ones_like(gx)), dim=1)  # (HW, 3), z = 1
    c2w = pose_inverse(poses)
    n = poses.shape[0]
    origin = c2w[:, :3].unsqueeze(1)  # (N, 1, 3)
    q = c2w[:, 3:].unsqueeze(1).expand(n, h * w, 4)
    dirs = pose_act(torch.cat((torch.zeros_like(q[..., :3]), q), dim=-1), rays_c.expand(n, -1, -1))
    lam = torch.full((n, h * w), SURF_Z0, dtype=torch.float64)
    for _ in range(RAY_ITERS):
        pts = origin + lam.unsqueeze(-1) * dirs
        lam = (_surface_z(pts[..., 0], pts[..., 1]) - origin[..., 2]) / dirs[..., 2]
    pts = origin + lam.unsqueeze(-1) * dirs
    return lam.reshape(n, h, w), pts  # ray z-component is 1 in the camera, so λ is the depth


def radius_edges(num_frames: int, radius: int, max_edges: int | None = None) -> tuple[Tensor, Tensor]:
    """Both directions of every pair 1 ≤ |i − j| ≤ radius, nearest first, at most ``max_edges``."""
    pairs = [(i, i + g) for g in range(1, radius + 1) for i in range(num_frames - g)]
    both = [p for a, b in pairs for p in ((a, b), (b, a))]
    if max_edges is not None:
        both = both[:max_edges]
    ii = torch.tensor([p[0] for p in both], dtype=torch.long)
    jj = torch.tensor([p[1] for p in both], dtype=torch.long)
    return ii, jj


def make_problem(num_frames: int = 12, h: int = 48, w: int = 64, radius: int = 3, max_edges: int | None = None,
                 channels: int = 32, movers: bool = False, mover_frames: tuple[int, ...] | None = None,
                 mover_box: tuple[float, float, float, float] = (0.2, 0.1, 0.75, 0.65),
                 mover_shift: tuple[float, float] = (1.5, 0.8), mover_beta: float = 0.8,
                 seed: int = 0) -> SyntheticProblem:
    """A synthetic problem (float32 state).  ``mover_box`` = (x0, y0, x1, y1) as fractions of W, H."""
    gen = torch.Generator().manual_seed(seed)
    intr = torch.tensor([0.9 * w, 0.9 * w, (w - 1) / 2.0, (h - 1) / 2.0], dtype=torch.float64)
    poses = camera_path(num_frames)
    depth, world = ray_cast_depth(poses, intr, h, w)
    disps = 1.0 / depth
    ii, jj = radius_edges(num_frames, radius, max_edges)
    coords, valid = reproject(poses, disps, intr, ii, jj, min_depth=0.05)
    omega = torch.randn(channels, 3, generator=gen, dtype=torch.float64) * FEATURE_FREQ
    phase = torch.rand(channels, generator=gen, dtype=torch.float64) * 2 * torch.pi
    feats = torch.cos(world @ omega.T + phase)  # (N, HW, C)
    mask = torch.zeros(num_frames, h, w, dtype=torch.bool)
    target = coords.clone()
    if movers:
        frames = tuple(range(num_frames)) if mover_frames is None else mover_frames
        x0, y0, x1, y1 = int(mover_box[0] * w), int(mover_box[1] * h), int(mover_box[2] * w), int(mover_box[3] * h)
        mask[list(frames), y0:y1, x0:x1] = True
        direction = torch.randn(channels, generator=gen, dtype=torch.float64)
        direction = direction / direction.norm()
        noise = torch.randn(num_frames, h * w, channels, generator=gen, dtype=torch.float64) / channels ** 0.5
        flat_mask = mask.reshape(num_frames, h * w)
        mover_feats = noise + mover_beta * direction
        feats = torch.where(flat_mask.unsqueeze(-1), mover_feats / mover_feats.norm(dim=-1, keepdim=True) * feats.norm(dim=-1, keepdim=True), feats)
        gap = (jj - ii).to(torch.float64).view(-1, 1, 1, 1)
        shift = torch.tensor(mover_shift, dtype=torch.float64).view(1, 1, 1, 2) * gap
        target = torch.where(mask[ii].unsqueeze(-1), target + shift, target)
    feats = feats / feats.norm(dim=-1, keepdim=True)
    inside = (target[..., 0] >= 0) & (target[..., 0] <= w - 1) & (target[..., 1] >= 0) & (target[..., 1] <= h - 1)
    weight = (valid & inside).unsqueeze(-1).expand(-1, -1, -1, 2).to(torch.float32)
    features = feats.transpose(1, 2).reshape(num_frames, channels, h, w).to(torch.float32)
    truth = BAState(poses=poses.float(), disps=disps.float(), intrinsics=intr.float(), features=features,
                    theta=torch.zeros(channels + 1))
    edges = EdgeSet(ii, jj, target.float(), weight)
    return SyntheticProblem(truth, edges, mask)


def perturb(state: BAState, trans: float = 0.03, rot_deg: float = 3.0, disp_rel: float = 0.2,
            fixed: int = 1, seed: int = 1) -> BAState:
    """Poses ≥ ``fixed`` moved by ~``trans`` m and ~``rot_deg``°, disparities scaled by U(1 ± disp_rel)."""
    gen = torch.Generator().manual_seed(seed)
    n = state.num_frames
    scale = torch.tensor([trans] * 3 + [rot_deg * torch.pi / 180.0] * 3)
    xi = (torch.rand(n, 6, generator=gen) * 2 - 1) * scale
    xi[:fixed] = 0
    poses = pose_compose(se3_exp(xi.double()), state.poses.double()).float()
    factor = 1.0 + disp_rel * (torch.rand(state.disps.shape, generator=gen) * 2 - 1)
    return state.with_(poses=poses, disps=state.disps * factor)


def max_pose_error(est: Tensor, truth: Tensor) -> tuple[float, float]:
    """(max translation error (m), max rotation error (rad)) of est·truth⁻¹ over frames."""
    dt, dr = pose_distance(est.double(), truth.double())
    return float(dt.max()), float(dr.max())
