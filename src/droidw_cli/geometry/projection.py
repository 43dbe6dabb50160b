"""Dense reprojection between keyframes and its fused analytic Jacobians (DROID-W Eq. 1).

Notation (one edge i → j, one grid pixel (u, v) of frame i with disparity d):

    x̄ = (u − cx)/fx,  ȳ = (v − cy)/fy            (normalised pixel of frame i)
    P = (X, Y, Z) = R_ij (x̄, ȳ, 1) + t_ij d       (homogeneous point (P, d) in frame j)
    G_ij = G_j G_i⁻¹ = (R_ij, t_ij)              (poses are world-to-camera)
    p_ij = (fx X/Z + cx, fy Y/Z + cy)

(P, d) is the point d·(x̄/d, ȳ/d, 1/d, 1), so its depth in frame i is 1/d and in
frame j it is Z/d.  A pixel is *valid* when d > 0, 1/d ≥ min_depth and
Z/d ≥ min_depth.  With x̂ = X/Z, ŷ = Y/Z, z = 1/Z the Jacobians are

    ∂p/∂ξ_j = [[fx d z, 0, −fx x̂ d z, −fx x̂ŷ,       fx (1 + x̂²), −fx ŷ],
               [0, fy d z, −fy ŷ d z, −fy (1 + ŷ²),  fy x̂ŷ,        fy x̂ ]]
    ∂p/∂ξ_i = −∂p/∂ξ_j · Ad(G_ij)                   (left perturbations, ξ = [v, ω])
    ∂p/∂d   = (fx z (t_x − x̂ t_z),  fy z (t_y − ŷ t_z))
    ∂p/∂fx  = (x̂ − x̄ z (R00 − x̂ R20),  −(fy/fx) x̄ z (R10 − ŷ R20))
    ∂p/∂fy  = (−(fx/fy) ȳ z (R01 − x̂ R21),  ŷ − ȳ z (R11 − ŷ R21))

(the intrinsics enter both Π⁻¹ in frame i and Π in frame j; cx, cy are fixed).
The focal unknowns are *log* focal lengths, fx ← fx·exp(δx), fy ← fy·exp(δy),
so their Jacobian rows are fx ∂p/∂fx and fy ∂p/∂fy: dimensionless like the
pose twist, which keeps the absolute pose damping (0.1) from swamping them.
For the ``shared`` mode one δ scales both (fy/fx is kept):
∂p/∂δ = fx ∂p/∂fx + fy ∂p/∂fy.  Everything is laid out "structure of
arrays" (E, ·, HW) so that pixel loops are tensor operations.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from droidw_cli.geometry.lie import adjoint_matrix, pose_compose, pose_inverse, pose_matrix

#: number of pose parameters (twist [v, ω])
POSE_DOF = 6
#: number of focal parameters per focal mode
FOCAL_DOF = {"none": 0, "shared": 1, "xy": 2}


def pixel_grid(h: int, w: int, device=None, dtype=torch.float32) -> tuple[Tensor, Tensor]:
    """Grid coordinates (x (HW,), y (HW,)) of every pixel, row-major (pixel (u, v) at x=u, y=v)."""
    y, x = torch.meshgrid(torch.arange(h, device=device, dtype=dtype),
                          torch.arange(w, device=device, dtype=dtype), indexing="ij")
    return x.reshape(-1), y.reshape(-1)


def relative_poses(poses: Tensor, ii: Tensor, jj: Tensor) -> tuple[Tensor, Tensor]:
    """(R_ij (E, 3, 3), t_ij (E, 3)) of G_ij = G_j G_i⁻¹ for world-to-camera poses (N, 7)."""
    gij = pose_compose(poses[jj], pose_inverse(poses[ii]))
    return pose_matrix(gij)


@dataclass(frozen=True)
class EdgeProjection:
    """The reprojection of every pixel of frame ii[k] into frame jj[k].

    Attributes:
        coords: (E, 2, HW) p_ij as (x, y); finite but meaningless where invalid.
        valid: (E, HW) bool, depth ≥ min_depth in both frames.
        x, y: (E, HW) x̂ = X/Z, ŷ = Y/Z.
        z: (E, HW) 1/Z (1 where invalid, to keep everything finite).
        disp: (E, HW) d of frame ii.
        rot, trans: R_ij (E, 3, 3), t_ij (E, 3).
        xbar, ybar: (HW,) normalised pixel coordinates of frame i.
    """

    coords: Tensor
    valid: Tensor
    x: Tensor
    y: Tensor
    z: Tensor
    disp: Tensor
    rot: Tensor
    trans: Tensor
    xbar: Tensor
    ybar: Tensor


def project_edges(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
                  min_depth: float) -> EdgeProjection:
    """Eq. 1 for every edge and pixel.  poses (N, 7), disps (N, H, W), intrinsics (4,)."""
    n, h, w = disps.shape
    fx, fy, cx, cy = intrinsics.unbind()
    gx, gy = pixel_grid(h, w, disps.device, disps.dtype)
    xbar, ybar = (gx - cx) / fx, (gy - cy) / fy
    rot, trans = relative_poses(poses, ii, jj)
    d = disps.reshape(n, h * w)[ii]
    ray = torch.stack((xbar, ybar, torch.ones_like(xbar)))  # (3, HW)
    pts = torch.matmul(rot, ray) + trans.unsqueeze(-1) * d.unsqueeze(1)  # (E, 3, HW)
    big_z = pts[:, 2]
    valid = (d > 0) & (d * min_depth <= 1.0) & (big_z >= min_depth * d)
    z = 1.0 / torch.where(valid, big_z, torch.ones_like(big_z))
    xn, yn = pts[:, 0] * z, pts[:, 1] * z
    coords = torch.stack((fx * xn + cx, fy * yn + cy), dim=1)
    return EdgeProjection(coords, valid, xn, yn, z, d, rot, trans, xbar, ybar)


def reproject(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
              min_depth: float = 0.05) -> tuple[Tensor, Tensor]:
    """p_ij for every pixel: (coords (E, H, W, 2) as (x, y), valid (E, H, W) bool)."""
    _, h, w = disps.shape
    proj = project_edges(poses, disps, intrinsics, ii, jj, min_depth)
    e = proj.coords.shape[0]
    return proj.coords.permute(0, 2, 1).reshape(e, h, w, 2), proj.valid.reshape(e, h, w)


def edge_jacobians(proj: EdgeProjection, intrinsics: Tensor, focal_mode: str = "none",
                   with_i: bool = True) -> tuple[Tensor, Tensor]:
    """The fused Jacobians of p_ij (see the module docstring).

    Returns:
        jac: (E, K, 2, HW) with K = 12 + nf rows: ∂p/∂ξ_i (0-5), ∂p/∂ξ_j (6-11),
            ∂p/∂log-focal (12..); axis 2 is the (x, y) component.  With
            ``with_i=False`` the ∂p/∂ξ_i rows are left out (K = 6 + nf); they are
            −Ad(G_ij)ᵀ times the ∂p/∂ξ_j rows.
        jac_d: (E, 2, HW) ∂p/∂d.
    """
    fx, fy = intrinsics[0], intrinsics[1]
    nf = FOCAL_DOF[focal_mode]
    x, y, z, d = proj.x, proj.y, proj.z, proj.disp
    e, hw = x.shape
    off = POSE_DOF if with_i else 0
    jac = x.new_empty(e, off + POSE_DOF + nf, 2, hw)
    dz = d * z
    xy = x * y
    jj_u, jj_v = jac[:, off:off + POSE_DOF, 0], jac[:, off:off + POSE_DOF, 1]
    jj_u[:, 0] = fx * dz
    jj_u[:, 1] = 0.0
    jj_u[:, 2] = -fx * x * dz
    jj_u[:, 3] = -fx * xy
    jj_u[:, 4] = fx * (1.0 + x * x)
    jj_u[:, 5] = -fx * y
    jj_v[:, 0] = 0.0
    jj_v[:, 1] = fy * dz
    jj_v[:, 2] = -fy * y * dz
    jj_v[:, 3] = -fy * (1.0 + y * y)
    jj_v[:, 4] = fy * xy
    jj_v[:, 5] = fy * x
    if with_i:
        adj = adjoint_matrix(proj.rot, proj.trans)  # (E, 6, 6)
        jac_j = jac[:, POSE_DOF:2 * POSE_DOF].reshape(e, POSE_DOF, 2 * hw)
        jac[:, :POSE_DOF] = torch.bmm(-adj.transpose(1, 2), jac_j).view(e, POSE_DOF, 2, hw)
    t = proj.trans
    jac_d = torch.stack((fx * z * (t[:, 0:1] - x * t[:, 2:3]), fy * z * (t[:, 1:2] - y * t[:, 2:3])), dim=1)
    if nf:
        r = proj.rot
        xb, yb = proj.xbar, proj.ybar
        dfx_u = x - xb * z * (r[:, 0, 0:1] - x * r[:, 2, 0:1])
        dfx_v = -(fy / fx) * xb * z * (r[:, 1, 0:1] - y * r[:, 2, 0:1])
        dfy_u = -(fx / fy) * yb * z * (r[:, 0, 1:2] - x * r[:, 2, 1:2])
        dfy_v = y - yb * z * (r[:, 1, 1:2] - y * r[:, 2, 1:2])
        k = off + POSE_DOF
        if focal_mode == "shared":
            jac[:, k, 0] = fx * dfx_u + fy * dfy_u
            jac[:, k, 1] = fx * dfx_v + fy * dfy_v
        else:
            jac[:, k, 0], jac[:, k, 1] = fx * dfx_u, fx * dfx_v
            jac[:, k + 1, 0], jac[:, k + 1, 1] = fy * dfy_u, fy * dfy_v
    return jac, jac_d
