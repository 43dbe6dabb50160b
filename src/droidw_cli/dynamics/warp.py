"""Predict a keyframe's colour and depth from other keyframes (backward warping).

The static map's "render" of ADD-SLAM is replaced by the reprojection of
neighbouring keyframes through the current poses and depths.  For target
keyframe t, source s and target pixel (u, v) with disparity d (inverse depth):

    x̄ = (u − cx)/fx,  ȳ = (v − cy)/fy
    X_t = (x̄, ȳ, 1)/d                                (target camera)
    X_s = R X_t + t,   (R, t) = G_s G_t⁻¹            (poses are world-to-camera)
    p_s = (fx X_s/Z_s + cx,  fy Y_s/Z_s + cy)        (pixel in source s)

Î(u, v) is the bilinear sample of the source colour at p_s (pixel centres at
integer coordinates, i.e. ``grid_sample(align_corners=True)``).  The predicted
depth is the source's own surface near p_s seen from the target: for each of
the candidates q — p_s itself with the bilinear disparity sample, and the four
bilinear corners (integer pixels) with their own disparities d_q —

    Y_q = ((q_x − cx)/fx, (q_y − cy)/fy, 1)/d_q,   Y_t = Rᵀ (Y_q − t),   D̂_q = Z(Y_t).

``depth_mode="closest"`` (default) keeps the candidate with the smallest
|D − D̂_q| (D = 1/d).  On smooth surfaces the bilinear candidate is accurate
to second order; at an occlusion edge the 1/8-grid disparities of the
foreground and the background would otherwise be blended into a depth that
belongs to neither and would make the foreground look "closer than
predicted" — the dynamic sign.  A real mover lands on a background
neighbourhood in the source, so all four corners disagree with it.
``depth_mode="bilinear"`` uses only the bilinear candidate.  The predicted
disparity is 1/D̂.

A prediction is valid when d > 0, Z_s ≥ min_depth, p_s lies in the source
image, the chosen candidate has disparity > 0 (for the bilinear one: all
four corners) and D̂ ≥ min_depth.  Where the target pixel shows a
static surface with correct depth and pose, Î = I and D̂ = D.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import Tensor

from droidw_cli.geometry.lie import pose_compose, pose_inverse, pose_matrix
from droidw_cli.geometry.projection import pixel_grid
from droidw_cli.geometry.sampling import bilinear_corners

DEPTH_MODES = ("closest", "bilinear")


def _check_inputs(images: Tensor, disps: Tensor, poses_w2c: Tensor, intrinsics: Tensor) -> None:
    if images.dim() != 4 or images.shape[-1] != 3:
        raise ValueError(f"images must be (K, h, w, 3), got {tuple(images.shape)}")
    if disps.dim() != 3 or disps.shape != images.shape[:3]:
        raise ValueError(f"disps must be (K, h, w) matching images {tuple(images.shape[:3])}, got {tuple(disps.shape)}")
    if poses_w2c.shape != (images.shape[0], 7):
        raise ValueError(f"poses_w2c must be ({images.shape[0]}, 7), got {tuple(poses_w2c.shape)}")
    if intrinsics.shape != (4,):
        raise ValueError(f"intrinsics must be (4,) fx, fy, cx, cy, got {tuple(intrinsics.shape)}")
    if images.shape[1] < 2 or images.shape[2] < 2:
        raise ValueError(f"images must be at least 2 × 2, got {images.shape[1]} × {images.shape[2]}")


def predict_views(images: Tensor, disps: Tensor, poses_w2c: Tensor, intrinsics: Tensor, target: int,
                  sources: Sequence[int], min_depth: float = 0.05,
                  depth_mode: str = "closest") -> tuple[Tensor, Tensor, Tensor]:
    """Warp the colour and depth of keyframes ``sources`` into keyframe ``target``.

    Args:
        images: (K, h, w, 3) float colour in [0, 1].
        disps: (K, h, w) inverse depth (≤ 0 means unknown).
        poses_w2c: (K, 7) world-to-camera poses [tx, ty, tz, qx, qy, qz, qw].
        intrinsics: (4,) fx, fy, cx, cy of this grid.
        target: index of the keyframe to predict.
        sources: indices of the keyframes to warp from (may be empty).
        min_depth: nearer points are invalid (metres).
        depth_mode: "closest" or "bilinear", see the module docstring.

    Returns:
        pred_rgb (S, h, w, 3), pred_disp (S, h, w) = 1/D̂ (0 where invalid),
        valid (S, h, w) bool — in the order of ``sources``.
    """
    _check_inputs(images, disps, poses_w2c, intrinsics)
    if depth_mode not in DEPTH_MODES:
        raise ValueError(f"depth_mode must be one of {DEPTH_MODES}, got {depth_mode!r}")
    k, h, w, _ = images.shape
    src = torch.as_tensor(list(sources), dtype=torch.long, device=disps.device)
    if not 0 <= target < k or bool(((src < 0) | (src >= k)).any()):
        raise ValueError(f"target {target} and sources {list(sources)} must index the {k} keyframes")
    dtype, device = disps.dtype, disps.device
    n = src.numel()
    if n == 0:
        return (images.new_zeros((0, h, w, 3)), disps.new_zeros((0, h, w)),
                torch.zeros((0, h, w), dtype=torch.bool, device=device))
    images = images.to(dtype)
    intrinsics = intrinsics.to(dtype=dtype, device=device)
    fx, fy, cx, cy = intrinsics.unbind()

    gx, gy = pixel_grid(h, w, device, dtype)
    ray = torch.stack(((gx - cx) / fx, (gy - cy) / fy, torch.ones_like(gx)))  # (3, HW)
    d = disps[target].reshape(-1)
    d_ok = d > 0
    depth_t = 1.0 / torch.where(d_ok, d, torch.ones_like(d))

    g = pose_compose(poses_w2c[src].to(dtype), pose_inverse(poses_w2c[target].to(dtype)).expand(n, 7))
    rot, trans = pose_matrix(g)  # (S, 3, 3), (S, 3)
    pts = torch.matmul(rot, ray * depth_t) + trans.unsqueeze(-1)  # (S, 3, HW)
    zs = pts[:, 2]
    z_ok = d_ok & (zs >= min_depth)
    zs_safe = torch.where(z_ok, zs, torch.ones_like(zs))
    px = fx * pts[:, 0] / zs_safe + cx
    py = fy * pts[:, 1] / zs_safe + cy
    inside = z_ok & (px >= 0) & (px <= w - 1) & (py >= 0) & (py <= h - 1)

    # bilinear colour, disparity and "disparity known" at p_s
    src_disp = disps[src]
    stack = torch.cat((images[src].permute(0, 3, 1, 2), src_disp.unsqueeze(1),
                       (src_disp > 0).to(dtype).unsqueeze(1)), dim=1)  # (S, 5, h, w)
    grid = torch.stack((torch.where(inside, px, torch.zeros_like(px)) * (2.0 / (w - 1)) - 1.0,
                        torch.where(inside, py, torch.zeros_like(py)) * (2.0 / (h - 1)) - 1.0), dim=-1)
    samp = F.grid_sample(stack, grid.reshape(n, h, w, 2), mode="bilinear", padding_mode="border",
                         align_corners=True).reshape(n, 5, h * w)
    rgb = samp[:, :3]

    # candidate source surfaces: the bilinear sample at p_s (+ the four corners for "closest")
    qx, qy, dq = px.unsqueeze(1), py.unsqueeze(1), samp[:, 3:4]  # (S, 1, HW)
    q_ok = (samp[:, 4:5] > 1.0 - 1e-4) & (dq > 0)
    if depth_mode == "closest":
        idx, _ = bilinear_corners(px, py, h, w)  # (4, S, HW) flat indices into one map
        idx = idx.permute(1, 0, 2)  # (S, 4, HW)
        dc = torch.gather(src_disp.reshape(n, 1, h * w).expand(n, 4, h * w), 2, idx)
        qx = torch.cat((qx, (idx % w).to(dtype)), 1)
        qy = torch.cat((qy, torch.div(idx, w, rounding_mode="floor").to(dtype)), 1)
        dq, q_ok = torch.cat((dq, dc), 1), torch.cat((q_ok, dc > 0), 1)
    # back-project the source surface at the corner(s) and express it in the target camera
    dq_safe = torch.where(q_ok, dq, torch.ones_like(dq))
    ray_q = torch.stack(((qx - cx) / fx, (qy - cy) / fy, torch.ones_like(qx)), dim=2)  # (S, Q, 3, HW)
    yq = ray_q / dq_safe.unsqueeze(2)
    yt = torch.einsum("sji,sqjp->sqip", rot, yq - trans.view(n, 1, 3, 1))
    dhat = yt[:, :, 2]  # (S, Q, HW)
    q_ok = q_ok & (dhat >= min_depth)
    gap = torch.where(q_ok, (dhat - depth_t).abs(), torch.full_like(dhat, float("inf")))
    best = gap.argmin(dim=1, keepdim=True)
    dhat = torch.gather(dhat, 1, best).squeeze(1)
    ok = inside & torch.gather(q_ok, 1, best).squeeze(1)
    pred_disp = torch.where(ok, 1.0 / torch.where(ok, dhat, torch.ones_like(dhat)), torch.zeros_like(dhat))
    pred_rgb = torch.where(ok.unsqueeze(1), rgb, torch.zeros_like(rgb))
    return (pred_rgb.permute(0, 2, 1).reshape(n, h, w, 3), pred_disp.reshape(n, h, w), ok.reshape(n, h, w))
