"""The hot path of one GN step in plain torch: residuals, weights, Jacobians, per-edge sums.

For edge k (frame i = ii[k] → j = jj[k]) and pixel p, with r = p*_ij − p_ij and
the weight

    w = weight_ij · flow_weight_scale · valid · f(u_i(p)) [· f(u_j(p_ij)) if bidirectional]

(f = :func:`droidw_cli.ba.uncertainty.weight_factor`) this accumulates

    hess[k] = Σ_p Σ_c w J Jᵀ     (J = rows [∂p/∂ξ_i, ∂p/∂ξ_j, ∂p/∂focal], K = 12 + nf)
    grad[k] = Σ_p Σ_c w J r
    E block = Σ_c w J ∂p/∂d      (per pixel, summed into the layout's (frame, node) blocks)
    C(i, p) += Σ_c w (∂p/∂d)²,   w(i, p) += Σ_c w (∂p/∂d) r

Edges are processed in chunks so that the temporaries stay below
``chunk_bytes``; the sums over pixels are batched matmuls (E, K, 2HW) @ (E, 2HW, K),
never per-pixel K × K outer products.
"""

from __future__ import annotations

import torch
from torch import Tensor

from droidw_cli.ba.params import BAParams
from droidw_cli.ba.schur import BlockLayout, LinearSystem
from droidw_cli.ba.uncertainty import weight_factor
from droidw_cli.geometry.lie import adjoint_matrix
from droidw_cli.geometry.projection import FOCAL_DOF, POSE_DOF, edge_jacobians, project_edges
from droidw_cli.geometry.sampling import sample_maps

#: temporaries per chunk of edges (bytes); bounds the memory of the hot path
DEFAULT_CHUNK_BYTES = 256 * 2**20
#: float32 tensors of size (K, 2, HW) alive per edge in a chunk (jac, weighted jac, E rows, slack)
_TEMPS_PER_EDGE = 5


def edge_chunks(num_edges: int, hw: int, k: int, chunk_bytes: int) -> list[slice]:
    """Slices of edges whose temporaries fit ``chunk_bytes``."""
    per_edge = _TEMPS_PER_EDGE * k * 2 * hw * 4
    size = max(1, chunk_bytes // per_edge)
    return [slice(s, min(s + size, num_edges)) for s in range(0, num_edges, size)]


def edge_weights(weight: Tensor, valid: Tensor, coords: Tensor, ii: Tensor, jj: Tensor, u_map: Tensor | None,
                 params: BAParams, h: int, w: int) -> Tensor:
    """w (E, 2, HW): confidence · scale · validity · uncertainty factors (module docstring)."""
    e = weight.shape[0]
    wt = weight.permute(0, 3, 1, 2).reshape(e, 2, h * w).contiguous() * (valid.unsqueeze(1) * params.flow_weight_scale)
    if u_map is not None:
        unc = params.uncertainty
        fac = weight_factor(u_map[ii], unc.mode)
        if unc.bidirectional:
            uj = sample_maps(u_map.reshape(-1, h, w), jj, coords[:, 0], coords[:, 1])
            fac = fac * weight_factor(uj, unc.mode)
        wt = wt * fac.unsqueeze(1)
    return wt


def expand_to_both_poses(adj: Tensor, hess_j: Tensor, grad_j: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(T, hess, grad) with T = [[−Adᵀ, 0], [I, 0], [0, I_nf]] so that J = T·[J_j; J_f].

    ∂p/∂ξ_i = −∂p/∂ξ_j·Ad(G_ij), so the rows of pose i are −Adᵀ times those of
    pose j: hess = T hess_j Tᵀ, grad = T grad_j.  hess_j (E, 6+nf, 6+nf).
    """
    e, kj = grad_j.shape
    nf = kj - POSE_DOF
    t = adj.new_zeros(e, POSE_DOF + kj, kj)
    t[:, :POSE_DOF, :POSE_DOF] = -adj.transpose(1, 2)
    t[:, POSE_DOF:] = torch.eye(kj, dtype=adj.dtype, device=adj.device)
    hess = torch.bmm(torch.bmm(t, hess_j), t.transpose(1, 2))
    grad = torch.bmm(t, grad_j.unsqueeze(2)).squeeze(2)
    return t, hess, grad


def linearize(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor, target: Tensor,
              weight: Tensor, u_map: Tensor | None, params: BAParams, layout: BlockLayout,
              chunk_bytes: int = DEFAULT_CHUNK_BYTES) -> LinearSystem:
    """The :class:`LinearSystem` of all edges.  u_map: (N, HW) uncertainty or None (unweighted).

    Only the pose-j (and focal) Jacobian rows are materialised; the pose-i rows
    follow from the adjoint (:func:`expand_to_both_poses`), which halves the work.
    """
    n, h, w = disps.shape
    hw = h * w
    e = ii.shape[0]
    nf = FOCAL_DOF[params.optimize_focal]
    kj = POSE_DOF + nf
    k = POSE_DOF + kj
    depth = not params.motion_only
    dev, dt = disps.device, disps.dtype
    hess = torch.empty(e, k, k, device=dev, dtype=dt)
    grad = torch.empty(e, k, device=dev, dtype=dt)
    cost = torch.zeros((), device=dev, dtype=dt)
    eblocks = torch.zeros(layout.num_blocks, POSE_DOF, hw, device=dev, dtype=dt) if depth else None
    cdiag = torch.zeros(n, hw, device=dev, dtype=dt) if depth else None
    wvec = torch.zeros(n, hw, device=dev, dtype=dt) if depth else None
    for sl in edge_chunks(e, hw, kj, chunk_bytes):
        ic, jc = ii[sl], jj[sl]
        ec = ic.shape[0]
        proj = project_edges(poses, disps, intrinsics, ic, jc, params.min_depth)
        jac, jac_d = edge_jacobians(proj, intrinsics, params.optimize_focal, with_i=False)  # (ec, kj, 2, HW)
        adj = adjoint_matrix(proj.rot, proj.trans)
        res = target[sl].permute(0, 3, 1, 2).reshape(ec, 2, hw).contiguous() - proj.coords
        wt = edge_weights(weight[sl], proj.valid, proj.coords, ic, jc, u_map, params, h, w)
        wres = wt * res
        cost += (wres * res).sum()
        flat = jac.view(ec, kj, 2 * hw)
        wjac = jac * wt.unsqueeze(1)
        hess_j = torch.bmm(wjac.view(ec, kj, 2 * hw), flat.transpose(1, 2))
        grad_j = torch.bmm(flat, wres.view(ec, 2 * hw, 1)).squeeze(2)
        t, hess[sl], grad[sl] = expand_to_both_poses(adj, hess_j, grad_j)
        if not depth:
            continue
        wjd = wt * jac_d
        cdiag.index_add_(0, ic, (wjd * jac_d).sum(1))
        wvec.index_add_(0, ic, (wjd * res).sum(1))
        erows = torch.addcmul(wjac[:, :, 0] * jac_d[:, 0:1], wjac[:, :, 1], jac_d[:, 1:2])  # (ec, kj, HW)
        scatter_eblocks(eblocks, layout.edge_blocks[sl], t, erows)
    return LinearSystem(hess, grad, eblocks, cdiag, wvec, cost)


def scatter_eblocks(eblocks: Tensor, blocks: Tensor, tmat: Tensor, erows: Tensor) -> None:
    """Add per-edge E rows (ec, 6+nf, HW) of pose j / focal into the layout's blocks.

    The pose-i rows are −Adᵀ times the pose-j rows (tmat from :func:`expand_to_both_poses`).
    """
    nf = erows.shape[1] - POSE_DOF
    eblocks.index_add_(0, blocks[:, 0], torch.bmm(tmat[:, :POSE_DOF, :POSE_DOF], erows[:, :POSE_DOF]))
    eblocks.index_add_(0, blocks[:, 1], erows[:, :POSE_DOF])
    if nf:
        eblocks[:, :nf].index_add_(0, blocks[:, 2], erows[:, POSE_DOF:])
