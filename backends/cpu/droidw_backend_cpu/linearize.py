"""The hot path of one GN step in plain torch: residuals, weights, Jacobians, per-edge sums.

For edge k (frame i = ii[k] → j = jj[k]), pixel p and component c ∈ {u, v} of
the residual r = p*_ij − p_ij, with the weight

    w = weight_ij · flow_weight_scale · valid · f(u_i(p)) [· f(u_j(p_ij)) if bidirectional]

(f = :func:`droidw_cli.ba.uncertainty.weight_factor`) this accumulates

    hess[k] = Σ_p Σ_c w J Jᵀ     (J = rows [∂p/∂ξ_i, ∂p/∂ξ_j, ∂p/∂focal], K = 12 + nf)
    grad[k] = Σ_p Σ_c w J r,     cost = Σ_k Σ_p Σ_c w r²
    erows[k](p) = Σ_c w J_j ∂p/∂d      (the edge's E rows of pose j and focal, 6 + nf per pixel)
    C(i, p) += Σ_c w (∂p/∂d)²,   w(i, p) += Σ_c w (∂p/∂d) r

**Square-root form.**  With s = √w every weighted sum is a plain Gram:
Σ w a b = Σ (s a)(s b).  The rows of ∂p/∂ξ_j (:mod:`droidw_cli.geometry.projection`)

    J_u = fx [d z, 0, −x̂ d z, −x̂ŷ, 1 + x̂², −ŷ],   J_v = fy [0, d z, −ŷ d z, −(1 + ŷ²), x̂ŷ, x̂]

have one structural zero each, so the u and v components are kept apart: per edge
A_c = s_c · [5 pose rows (signs below), focal rows, r_c] ((2, 6 + nf, HW)), and
one batched Gram A_c A_cᵀ gives, after the constant signed selections P_c,

    Σ_c P_c (A_c A_cᵀ) P_cᵀ = [[H_j, g_j], [g_jᵀ, Σ w r²]].

The stored rows are s·f·[d z, x̂ d z, x̂ŷ, 1 + x̂², −ŷ] for u and
s·f·[d z, ŷ d z, 1 + ŷ², x̂ŷ, x̂] for v (pose-j rows 0, 2, 3, 4, 5 and
1, 2, 3, 4, 5); the remaining signs (+, −, −, +, +) of both go into P.  With
b_c = s_c ∂p_c/∂d the per-pixel terms are C = Σ_c b_c², w = Σ_c b_c (s_c r_c)
and erows = Σ_c (s_c J_c) b_c, all elementwise.

Only the pose-j (and focal) rows are built; the pose-i rows follow from the
adjoint (:func:`expand_to_both_poses`).  Edges go in chunks whose temporaries stay
below ``chunk_bytes``; ``erows`` (E, 6 + nf, HW) is the one output that grows with
the pixels, and :func:`droidw_cli.ba.schur.solve_step` takes it as it is (one E
block per edge, the "edge form").  The reprojection comes from a
:class:`~droidw_backend_cpu.reproject.ProjectionCache` when it holds these edges
for this state (the tracker's evidence maps or uncertainty step made it), else
it is computed per chunk.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from droidw_cli.ba.params import BAParams
from droidw_cli.ba.schur import BlockLayout, LinearSystem
from droidw_cli.ba.uncertainty import weight_factor
from droidw_cli.geometry.lie import adjoint_matrix
from droidw_cli.geometry.projection import FOCAL_DOF, POSE_DOF
from droidw_backend_cpu.reproject import FrameGeometry, ProjectionCache, Projected, sample_scalar

#: temporaries per chunk of edges (bytes); bounds the memory of the hot path
DEFAULT_CHUNK_BYTES = 24 * 2**20
#: (HW,) tensors of the working dtype alive per edge of a chunk (A: 2·(6 + nf), the rest about 30)
_TEMPS_PER_EDGE = 44
#: pose-j row of each stored Jacobian row (rows 0-4) of the u and v components, and its sign
_U_ROWS = (0, 2, 3, 4, 5)
_V_ROWS = (1, 2, 3, 4, 5)
_SIGNS = (1.0, -1.0, -1.0, 1.0, 1.0)


def edge_chunks(num_edges: int, hw: int, nf: int, chunk_bytes: int, itemsize: int = 4) -> list[slice]:
    """Slices of edges whose temporaries fit ``chunk_bytes``."""
    per_edge = (_TEMPS_PER_EDGE + 2 * nf) * hw * itemsize
    size = max(1, chunk_bytes // per_edge)
    return [slice(s, min(s + size, num_edges)) for s in range(0, num_edges, size)]


def selection_matrices(nf: int, dtype: torch.dtype, device: torch.device) -> Tensor:
    """P (2, 7 + nf, 6 + nf): stored row of component c → signed row of [ξ_j (6), focal (nf), r]."""
    p = torch.zeros(2, POSE_DOF + nf + 1, POSE_DOF + nf, dtype=dtype, device=device)
    for c, rows in enumerate((_U_ROWS, _V_ROWS)):
        for stored, (row, sign) in enumerate(zip(rows, _SIGNS)):
            p[c, row, stored] = sign
        for f in range(nf + 1):  # focal rows and the residual row map straight through
            p[c, POSE_DOF + f, 5 + f] = 1.0
    return p


def expand_to_both_poses(adj: Tensor, hess_j: Tensor, grad_j: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(T, hess, grad) with T = [[−Adᵀ, 0], [I, 0], [0, I_nf]] so that J = T·[J_j; J_f].

    ∂p/∂ξ_i = −∂p/∂ξ_j·Ad(G_ij), so the rows of pose i are −Adᵀ times those of
    pose j: hess = T hess_j Tᵀ, grad = T grad_j.  hess_j (E, 6+nf, 6+nf).
    """
    e, kj = grad_j.shape
    t = adj.new_zeros(e, POSE_DOF + kj, kj)
    t[:, :POSE_DOF, :POSE_DOF] = -adj.transpose(1, 2)
    t[:, POSE_DOF:] = torch.eye(kj, dtype=adj.dtype, device=adj.device)
    hess = torch.bmm(torch.bmm(t, hess_j), t.transpose(1, 2))
    grad = torch.bmm(t, grad_j.unsqueeze(2)).squeeze(2)
    return t, hess, grad


def frame_weight_roots(u_map: Tensor | None, params: BAParams, n: int, hw: int, like: Tensor) -> Tensor:
    """√(flow_weight_scale · f(u_i)) per frame and pixel (N, HW) (f ≡ 1 without u_map)."""
    if u_map is None:
        return like.new_full((n, hw), math.sqrt(params.flow_weight_scale))
    fac = weight_factor(u_map.to(like.dtype), params.uncertainty.mode)
    return (fac * params.flow_weight_scale).sqrt_()


def _focal_rows(a: Tensor, s: Tensor, xy: Tensor, z: Tensor, rot: Tensor, xbar: Tensor, ybar: Tensor,
                fx: float, fy: float, focal_mode: str) -> None:
    """Write s·∂p/∂log f into a[:, c, 5:5+nf] (see :mod:`droidw_cli.geometry.projection`)."""
    x, y = xy[:, 0], xy[:, 1]
    r = rot
    dfx_u = x - xbar * z * (r[:, 0, 0:1] - x * r[:, 2, 0:1])
    dfx_v = -(fy / fx) * xbar * z * (r[:, 1, 0:1] - y * r[:, 2, 0:1])
    dfy_u = -(fx / fy) * ybar * z * (r[:, 0, 1:2] - x * r[:, 2, 1:2])
    dfy_v = y - ybar * z * (r[:, 1, 1:2] - y * r[:, 2, 1:2])
    if focal_mode == "shared":
        a[:, 0, 5] = s[:, 0] * (fx * dfx_u + fy * dfy_u)
        a[:, 1, 5] = s[:, 1] * (fx * dfx_v + fy * dfy_v)
    else:
        a[:, 0, 5], a[:, 1, 5] = s[:, 0] * (fx * dfx_u), s[:, 1] * (fx * dfx_v)
        a[:, 0, 6], a[:, 1, 6] = s[:, 0] * (fy * dfy_u), s[:, 1] * (fy * dfy_v)


def linearize(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor, target: Tensor,
              weight: Tensor, u_map: Tensor | None, params: BAParams, layout: BlockLayout | None = None,
              chunk_bytes: int = DEFAULT_CHUNK_BYTES, projections: ProjectionCache | None = None) -> LinearSystem:
    """The :class:`LinearSystem` (edge form) of all edges.  u_map: (N, HW) uncertainty or None (unweighted).

    ``layout`` is not needed by the edge form (kept for the backends' common hook signature).
    ``projections``: a cache whose projection of these edges (same state) is used when present.
    """
    n, h, w = disps.shape
    hw = h * w
    e = ii.shape[0]
    nf = FOCAL_DOF[params.optimize_focal]
    kj = POSE_DOF + nf
    rows = kj  # stored rows per component: 5 pose, nf focal, residual
    depth = not params.motion_only
    dev, dt = disps.device, disps.dtype
    unc = params.uncertainty
    geo = FrameGeometry(poses, disps, intrinsics, params.min_depth)
    fx, fy, focal = geo.fx, geo.fy, geo.focal
    roots = frame_weight_roots(u_map, params, n, hw, geo.dflat)
    sel = selection_matrices(nf, dt, dev)
    cached = None if projections is None else projections.peek(poses, disps, intrinsics, ii, jj, params.min_depth)
    rot_all, trans_all = geo.relative(ii, jj) if cached is None else cached[1:]

    system = torch.empty(e, kj + 1, kj + 1, device=dev, dtype=dt)
    erows = torch.empty(e, kj, hw, device=dev, dtype=dt) if depth else None
    cdiag = torch.zeros(n, hw, device=dev, dtype=dt) if depth else None
    wvec = torch.zeros(n, hw, device=dev, dtype=dt) if depth else None
    for sl in edge_chunks(e, hw, nf, chunk_bytes, disps.element_size()):
        ic, jc = ii[sl], jj[sl]
        ec = ic.shape[0]
        rot, trans = rot_all[sl], trans_all[sl]
        if cached is None:
            proj = geo.project(ic, rot, trans)
        else:
            full = cached[0]
            proj = Projected(full.xy[sl], full.coords[sl], full.z[sl], full.disp[sl], full.valid[sl])
        xy, coords, z, d, valid = proj.xy, proj.coords, proj.z, proj.disp, proj.valid
        a = torch.empty(ec, 2, rows, hw, device=dev, dtype=dt)  # s·[5 pose rows, focal rows, r] of u and v
        res = torch.sub(target[sl].reshape(ec, hw, 2).transpose(1, 2), coords, out=a[:, :, rows - 1])
        # s = √w (component-wise), zero where invalid
        s = torch.sqrt(weight[sl].reshape(ec, hw, 2).transpose(1, 2), out=torch.empty_like(coords))
        s.mul_(roots.index_select(0, ic).mul_(valid).unsqueeze(1))
        if u_map is not None and unc.bidirectional:
            uj = sample_scalar(u_map.to(dt).reshape(n, h, w), jc, coords[:, 0], coords[:, 1])
            s.mul_(weight_factor(uj, unc.mode).sqrt_().unsqueeze(1))
        sf = s * focal  # s·f
        sz = sf * z.unsqueeze(1)  # s·f·z
        torch.mul(sz, d.unsqueeze(1), out=a[:, :, 0])  # s f d z (u and v)
        torch.mul(a[:, :, 0], xy, out=a[:, :, 1])  # s f d z x̂ | s f d z ŷ
        x, y = xy[:, 0], xy[:, 1]
        xyp = x * y
        sq = torch.mul(xy, xy)  # x̂², ŷ²
        torch.mul(sf[:, 0], xyp, out=a[:, 0, 2])
        torch.addcmul(sf[:, 1], sf[:, 1], sq[:, 1], out=a[:, 1, 2])  # s f (1 + ŷ²)
        torch.addcmul(sf[:, 0], sf[:, 0], sq[:, 0], out=a[:, 0, 3])  # s f (1 + x̂²)
        torch.mul(sf[:, 1], xyp, out=a[:, 1, 3])
        torch.mul(sf[:, 0], y, out=a[:, 0, 4]).neg_()
        torch.mul(sf[:, 1], x, out=a[:, 1, 4])
        if nf:
            _focal_rows(a, s, xy, z, rot, geo.xbar, geo.ybar, fx, fy, params.optimize_focal)
        res.mul_(s)  # row r: s·r
        gram = torch.bmm(a.view(ec * 2, rows, hw), a.view(ec * 2, rows, hw).transpose(1, 2))
        system[sl] = torch.matmul(torch.matmul(sel, gram.view(ec, 2, rows, rows)), sel.transpose(1, 2)).sum(1)
        if not depth:
            continue
        # b = s ∂p/∂d = s f z (t_xy − (x̂, ŷ) t_z)
        b = torch.addcmul(trans[:, :2].unsqueeze(2), xy, trans[:, 2:3].unsqueeze(2), value=-1.0).mul_(sz)
        cdiag.index_add_(0, ic, torch.mul(b, b).sum(1))
        wvec.index_add_(0, ic, torch.mul(b, a[:, :, rows - 1]).sum(1))
        er = erows[sl]
        torch.mul(a[:, :, 0], b, out=er[:, 0:2])
        torch.mul(a[:, 0, 1:rows - 1], b[:, 0:1], out=er[:, 2:])
        er[:, 2:].addcmul_(a[:, 1, 1:rows - 1], b[:, 1:2])
        er[:, 2:4].neg_()
    hess_j = system[:, :kj, :kj]
    grad_j = system[:, :kj, kj]
    cost = system[:, kj, kj].sum()
    tmat, hess, grad = expand_to_both_poses(adjoint_matrix(rot_all, trans_all), hess_j, grad_j)
    return LinearSystem(hess, grad, None, cdiag, wvec, cost, erows=erows, tmat=tmat if depth else None)


def scatter_eblocks(eblocks: Tensor, blocks: Tensor, tmat: Tensor, erows: Tensor) -> None:
    """Add per-edge E rows (ec, 6+nf, HW) of pose j / focal into the layout's blocks (block form).

    The pose-i rows are −Adᵀ times the pose-j rows (tmat from :func:`expand_to_both_poses`).
    """
    nf = erows.shape[1] - POSE_DOF
    eblocks.index_add_(0, blocks[:, 0], torch.bmm(tmat[:, :POSE_DOF, :POSE_DOF], erows[:, :POSE_DOF]))
    eblocks.index_add_(0, blocks[:, 1], erows[:, :POSE_DOF])
    if nf:
        eblocks[:, :nf].index_add_(0, blocks[:, 2], erows[:, POSE_DOF:])
