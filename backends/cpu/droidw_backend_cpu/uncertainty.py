"""The data term γ_data·E_sim of the uncertainty objective and its ∂/∂u map, in torch.

See :mod:`droidw_cli.ba.uncertainty` for the objective.  Per E_sim edge k and
pixel p of frame i: F_ij = Σ_c w_c F_j[corner c] (bilinear, border-clamped),
s from cos(F_i, F_ij), u_ij = Σ_c w_c u_j[corner c], and

    t = ω_k γ_data valid (1 − s) / (u_i u_ij)
    G[i, p] −= t / u_i,      G[j, corner c] −= w_c t / u_ij.

Features are gathered channel-last in chunks of edges (memory bounded by
``chunk_bytes``), so nothing of size (E, C, HW) is held at once.
"""

from __future__ import annotations

import torch
from torch import Tensor

from droidw_cli.ba.uncertainty import COS_EPS, similarity_score
from droidw_cli.geometry.projection import project_edges
from droidw_cli.geometry.sampling import bilinear_corners, inside_image

#: bytes of gathered features per chunk of edges
DEFAULT_FEATURE_CHUNK_BYTES = 64 * 2**20
#: gathered (HW, C) float32 tensors alive per edge (corner sample, accumulated F_ij, F_i)
_FEATURE_TEMPS = 3


def similarity_data_term(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
                         omega: Tensor, features: Tensor, u: Tensor, gamma_data: float, sim_threshold: float,
                         min_depth: float, chunk_bytes: int = DEFAULT_FEATURE_CHUNK_BYTES,
                         target: Tensor | None = None, geo_sigma: float = 0.0) -> tuple[Tensor, Tensor]:
    """(G (N, HW) = ∂(γ_data E_sim)/∂u, γ_data E_sim as a 0-d tensor) over the E_sim edges ii, jj.

    features (N, C, H, W) any float dtype; u (N, HW) float32; omega (K,) edge weights;
    target (K, H, W, 2) the correspondence targets of these edges, used by the
    geometric factor of s when ``geo_sigma`` > 0.
    """
    n, c, h, w = features.shape
    hw = h * w
    fcl = features.reshape(n, c, hw).transpose(1, 2).float().contiguous()  # (N, HW, C)
    fnorm = fcl.norm(dim=2)  # (N, HW)
    flat = fcl.reshape(n * hw, c)
    uflat = u.reshape(-1)
    grad = torch.zeros(n * hw, dtype=torch.float32, device=u.device)
    loss = torch.zeros((), dtype=torch.float32, device=u.device)
    pix = torch.arange(hw, device=u.device)
    size = max(1, chunk_bytes // (_FEATURE_TEMPS * hw * c * 4))
    for s0 in range(0, ii.shape[0], size):
        ic, jc, om = ii[s0:s0 + size], jj[s0:s0 + size], omega[s0:s0 + size]
        proj = project_edges(poses, disps, intrinsics, ic, jc, min_depth)
        x, y = proj.coords[:, 0], proj.coords[:, 1]
        valid = proj.valid & inside_image(x, y, h, w)
        idx, wts = bilinear_corners(x, y, h, w)
        idx = idx + (jc * hw).view(1, -1, 1)  # (4, ec, HW) flat into (N·HW)
        fij = wts[0].unsqueeze(2) * flat[idx[0]]
        for corner in range(1, 4):
            fij += wts[corner].unsqueeze(2) * flat[idx[corner]]
        dot = (fij * fcl[ic]).sum(2)
        cos = dot / (fij.norm(dim=2) * fnorm[ic]).clamp_min(COS_EPS)
        residual = None
        if target is not None and geo_sigma > 0:
            tc = target[s0:s0 + size].reshape(-1, hw, 2)
            residual = torch.hypot(tc[..., 0] - x, tc[..., 1] - y)
        sim = similarity_score(cos, sim_threshold, residual, geo_sigma)
        iflat = ic.unsqueeze(1) * hw + pix  # (ec, HW)
        ui = uflat[iflat]
        uij = (uflat[idx] * wts).sum(0)
        t = gamma_data * om.unsqueeze(1) * valid * (1.0 - sim) / (ui * uij)
        loss += t.sum()
        grad.index_add_(0, iflat.reshape(-1), (-t / ui).reshape(-1))
        gij = -t / uij
        grad.index_add_(0, idx.reshape(-1), (wts * gij.unsqueeze(0)).reshape(-1))
    return grad.reshape(n, hw), loss
