"""Block-sparse Schur complement and the Gauss-Newton update (DROID-W Eq. 4-5).

The normal equations of one GN step, with pose-like unknowns Δξ (6 per pose,
plus the focal parameters as one extra "node") and one disparity per pixel:

    [ B   E ] [Δξ]   [v]
    [ Eᵀ  C ] [Δd] = [w],        C diagonal (one entry per pixel).

A pixel p of frame n is observed only through edges k with ii[k] = n, and each
such edge couples it to pose ii[k], pose jj[k] (and the focal node).  No dense
6P × (N·HW) matrix is ever formed; E comes in one of two sparse forms.

**Edge form** (CPU backend): one (6 + nf, HW) block e_k per edge, the rows of
pose jj[k] (and focal); the edge's full E rows are T_k e_k with
T_k = [[−Ad(G_ij)ᵀ, 0], [I, 0], [0, I_nf]] (``LinearSystem.tmat``).  With edges
grouped by their depth frame n (:func:`edge_groups`) and
Γ_kl = Σ_p e_k C_n⁻¹ e_lᵀ for k, l ∈ out(n),

    S = B − Σ_n Σ_{k,l ∈ out(n)} T_k Γ_kl T_lᵀ,     rhs = v − Σ_k T_k Σ_p e_k C⁻¹ w,

scattered to the node pairs (ii, jj, f)_k × (ii, jj, f)_l: pose-pair blocks
exist only where two poses share a depth frame.  Frames with the same
out-degree D form one batched matmul (n_D, (6+nf)D, HW) @ (n_D, HW, (6+nf)D).
Back-substitution: (Eᵀ Δξ)_n = Σ_{k ∈ out(n)} e_kᵀ T_kᵀ [Δξ_i; Δξ_j; Δf].

**Block form** (CUDA backend): one (6, HW) block per distinct pair (depth
frame n, pose node m), the sum over n's edges (:class:`BlockLayout`), and

    S = B − Σ_n Σ_{a,b ∈ blocks(n)} E_a C_n⁻¹ E_bᵀ,      rhs = v − Σ E_a C_n⁻¹ w_n

grouped by block count D the same way.  Both forms give the same S up to
round-off (the edge form's Grams are smaller: D edges instead of D + 1 blocks).

S lives in float64 on the active nodes only (poses ≥ t0 that appear in an
edge, plus the focal node), is damped diag += rel·diag + abs and solved by
Cholesky; a failed factorisation gives a zero step.  Then
Δd = C⁻¹ (w − Eᵀ Δξ), T ← Exp(Δξ)·T, d ← max(d + Δd, min_disp).

The focal node's block has only nf ∈ {1, 2} meaningful rows; its padding rows
are zero in B and E and get a unit diagonal so that they solve to 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from droidw_cli.ba.params import BAParams
from droidw_cli.geometry.lie import normalize_pose, pose_compose, se3_exp
from droidw_cli.geometry.projection import FOCAL_DOF, POSE_DOF


@dataclass(frozen=True)
class BlockLayout:
    """Where each edge's E rows go.  Nodes 0..N−1 are poses, node N the focal node.

    Blocks are ordered by (number of blocks of their frame, frame, node), so the
    blocks of all frames with D blocks form one contiguous range.

    Attributes:
        num_frames: N.
        num_nodes: N (+1 with a focal node).
        nf: number of focal parameters (0, 1, 2).
        block_frame, block_node: (Q,) depth frame and node of each E block.
        edge_blocks: (E, 2 or 3) block index of the edge's i-, j- (and focal) rows.
        groups: list of (D, start, count): ``count`` frames with D blocks each,
            blocks start .. start + count·D.
    """

    num_frames: int
    num_nodes: int
    nf: int
    block_frame: Tensor
    block_node: Tensor
    edge_blocks: Tensor
    groups: list[tuple[int, int, int]]

    @property
    def num_blocks(self) -> int:
        return int(self.block_frame.shape[0])


def build_layout(ii: Tensor, jj: Tensor, num_frames: int, focal_mode: str = "none") -> BlockLayout:
    """The E-block structure of the edges (ii, jj) (see :class:`BlockLayout`)."""
    nf = FOCAL_DOF[focal_mode]
    m = num_frames + (1 if nf else 0)
    parts = [ii * m + ii, ii * m + jj]
    if nf:
        parts.append(ii * m + num_frames)
    keys = torch.stack(parts, dim=1)  # (E, 2|3)
    uniq, inverse = torch.unique(keys.reshape(-1), sorted=True, return_inverse=True)
    frame, node = uniq // m, uniq % m
    per_frame = torch.bincount(frame, minlength=num_frames)
    order = torch.argsort(per_frame[frame] * m * m + uniq, stable=True)
    position = torch.empty_like(order)
    position[order] = torch.arange(order.shape[0], device=order.device)
    frame, node = frame[order], node[order]
    counts = per_frame[frame]
    groups = []
    start = 0
    for d, total in zip(*(t.tolist() for t in torch.unique_consecutive(counts, return_counts=True))):
        groups.append((int(d), start, int(total) // int(d)))
        start += int(total)
    return BlockLayout(num_frames, m, nf, frame, node, position[inverse].reshape(keys.shape), groups)


@dataclass
class LinearSystem:
    """The linearisation a backend hands to :func:`solve_step` (float32).

    E is given either in block form (``eblocks``) or in edge form (``erows`` and
    ``tmat``); both None means motion-only.

    Attributes:
        hess: (E, K, K) per-edge Σ w JᵀJ over the pose-like rows, K = 12 + nf
            (rows 0-5 pose ii, 6-11 pose jj, 12.. focal).
        grad: (E, K) per-edge Σ w Jᵀ r.
        eblocks: (Q, 6, HW) E blocks Σ w J_node ∂p/∂d of the :class:`BlockLayout`, or None.
        cdiag: (N, HW) Σ w (∂p/∂d)² per pixel, *without* damping or prior.
        wvec: (N, HW) Σ w (∂p/∂d) r per pixel, without the prior.
        cost: 0-d tensor, Σ w r².
        erows: (E, 6 + nf, HW) per-edge E rows Σ w [J_jj; J_f] ∂p/∂d, or None.
        tmat: (E, K, 6 + nf) T_k with [J_ii; J_jj; J_f] = T_k [J_jj; J_f] (with ``erows``).
        gram_dtype: dtype in which the edge form's Schur Grams Γ_kl = Σ_p e_k C⁻¹ e_lᵀ and
            Σ_p e_k C⁻¹ w are accumulated; None = ``erows``' own dtype.  The rows e_k C^-1/2
            are formed per pixel in float32 either way; float64 accumulation (the CUDA
            backend) keeps the B − E C⁻¹ Eᵀ cancellation of a poorly conditioned window
            from amplifying float32 sums into the step.
    """

    hess: Tensor
    grad: Tensor
    eblocks: Tensor | None
    cdiag: Tensor | None
    wvec: Tensor | None
    cost: Tensor
    erows: Tensor | None = None
    tmat: Tensor | None = None
    gram_dtype: torch.dtype | None = None

    @property
    def has_depth(self) -> bool:
        """True when the system has the disparity block (not motion-only)."""
        return self.eblocks is not None or self.erows is not None


def depth_system(lin: LinearSystem, disps: Tensor, depth_prior: Tensor | None,
                 params: BAParams) -> tuple[Tensor, Tensor, Tensor]:
    """(C⁻¹, w, prior cost): add γ_d(d − D)² where D > 0 and the damping to C."""
    n = disps.shape[0]
    c, w = lin.cdiag, lin.wvec
    d = disps.reshape(n, -1)
    if depth_prior is not None:
        prior = depth_prior.reshape(n, -1).to(d)
        has = prior > 0
        g = params.gamma_depth * has.float()
        c = c + g + torch.where(has, params.prior_damping, params.depth_damping)
        w = w + g * (prior - d)
        prior_cost = (g * (d - prior) ** 2).sum()
    else:
        c = c + params.depth_damping
        prior_cost = d.new_zeros(())
    return 1.0 / c, w, prior_cost


def _block_index(node_a: Tensor, node_b: Tensor, active: Tensor, num_active: int) -> Tensor:
    """Flat slot a·A + b of the node pairs (active[a], active[b]); A·A (a sink) where either is inactive."""
    a, b = active[node_a].reshape(-1), active[node_b].reshape(-1)
    return torch.where((a >= 0) & (b >= 0), a * num_active + b, num_active * num_active)


def _scatter_blocks(dest: Tensor, node_a: Tensor, node_b: Tensor, blocks: Tensor, active: Tensor) -> None:
    """dest (A·A + 1, 6, 6) += blocks (..., 6, 6) at (active[a], active[b]); inactive pairs go to the sink."""
    na = int(round((dest.shape[0] - 1) ** 0.5))
    dest.index_add_(0, _block_index(node_a, node_b, active, na), blocks.reshape(-1, POSE_DOF, POSE_DOF).to(dest.dtype))


#: rows of one batch of frames of the edge-form Schur Grams (bytes): small enough to stay in cache
SCHUR_BATCH_BYTES = 8 * 2**20


def edge_groups(ii: Tensor, num_frames: int) -> tuple[Tensor, list[tuple[int, int, int]]]:
    """(order (E,), groups): edges sorted by (out-degree D of their frame ii, ii), stably.

    ``groups`` lists (D, start, count): ``count`` frames with D out-edges each,
    edges ``order[start : start + count·D]``, D consecutive edges per frame.
    """
    degree = torch.bincount(ii, minlength=num_frames)
    order = torch.argsort(degree[ii] * num_frames + ii, stable=True)
    vals, counts = torch.unique_consecutive(degree[ii[order]], return_counts=True)
    groups = []
    start = 0
    for d, total in zip(vals.tolist(), counts.tolist()):
        groups.append((int(d), start, int(total) // int(d)))
        start += int(total)
    return order, groups


def _pad_blocks(t: Tensor, nb: int, dims: int) -> Tensor:
    """Zero-pad the last ``dims`` axes of t (each K ≤ 6·nb long) to 6·nb."""
    pad = nb * POSE_DOF - t.shape[-1]
    return torch.nn.functional.pad(t, (0, pad) * dims) if pad else t


def _edge_form_schur(s_blocks: Tensor, rhs: Tensor, lin: LinearSystem, ii: Tensor, nodes: Tensor, cinv: Tensor,
                     wvec: Tensor, active: Tensor, slot: Tensor) -> None:
    """Subtract Σ T_k Γ_kl T_lᵀ from S and Σ T_k e_k C⁻¹ w from rhs (edge form, module docstring).

    Per group of frames with D out-edges: a = [e_k C^-1/2 (k ∈ out(n)); w_n C^-1/2] (one more
    row per frame, and a zero row to keep the row count even, which MKL's small
    Grams run much faster on), so one batched Gram a aᵀ holds both Γ and Σ_p e_k C⁻¹ w.
    """
    e, kj, hw = lin.erows.shape
    nb = nodes.shape[1]
    order, groups = edge_groups(ii, cinv.shape[0])
    root = cinv.sqrt()
    wroot = wvec * root
    gram_dtype = lin.gram_dtype or lin.erows.dtype
    itemsize = torch.empty((), dtype=gram_dtype).element_size()
    batches = []  # (D, first edge, frames): each group in batches of frames whose rows fit SCHUR_BATCH_BYTES
    for d, start, count in groups:
        per_frame = (d * kj + 2) * hw * itemsize
        step = max(1, SCHUR_BATCH_BYTES // per_frame)
        batches += [(d, start + f * d, min(step, count - f)) for f in range(0, count, step)]
    num_active = int(round((s_blocks.shape[0] - 1) ** 0.5))
    s_at, s_add, rhs_at, rhs_add = [], [], [], []
    for d, start, count in batches:
        sel = order[start:start + count * d]
        frames = ii[sel[::d]]  # (count,) the depth frame of each group member
        m = d * kj
        rows = m + 1 + (m + 1) % 2
        a = torch.empty(count, rows, hw, dtype=gram_dtype, device=lin.erows.device)
        # e_k C^-1/2; index_select, not x[sel]: advanced indexing gathers element by element, far slower on CPU
        torch.mul(lin.erows.index_select(0, sel).view(count, d, kj, hw),
                  root.index_select(0, frames).view(count, 1, 1, hw), out=a[:, :m].view(count, d, kj, hw))
        a[:, m] = wroot.index_select(0, frames)  # w C^-1/2
        a[:, m + 1:] = 0.0
        gram = torch.bmm(a, a.transpose(1, 2)).double()
        g = gram[:, :m, :m].reshape(count, d, kj, d, kj).transpose(2, 3)  # Γ_kl
        ew = gram[:, :m, m].reshape(count, d, kj, 1)  # Σ_p e_k C⁻¹ w
        t = lin.tmat[sel].double().reshape(count, d, 1, -1, kj)
        tew = _pad_blocks(torch.matmul(t[:, :, 0], ew).reshape(count * d, -1), nb, 1)  # T_k Σ_p e_k C⁻¹ w
        nd = nodes[sel].reshape(count, d, nb)
        rhs_at.append(slot[nd.reshape(-1)])
        rhs_add.append(-tew.reshape(-1, POSE_DOF))
        prod = _pad_blocks(torch.matmul(torch.matmul(t, g), t.transpose(1, 2).transpose(3, 4)), nb, 2)
        prod = prod.reshape(count, d, d, nb, POSE_DOF, nb, POSE_DOF).transpose(4, 5)  # (c, k, l, a, b, 6, 6)
        shape = (count, d, d, nb, nb)
        s_at.append(_block_index(nd[:, :, None, :, None].expand(shape), nd[:, None, :, None, :].expand(shape),
                                 active, num_active))
        s_add.append(-prod.reshape(-1, POSE_DOF, POSE_DOF))
    # one scatter for all batches (each index_add_ call has a fixed cost that small windows feel)
    s_blocks.index_add_(0, torch.cat(s_at), torch.cat(s_add))
    rhs.index_add_(0, torch.cat(rhs_at), torch.cat(rhs_add))


def _block_form_schur(s_blocks: Tensor, rhs: Tensor, lin: LinearSystem, layout: BlockLayout, cinv: Tensor,
                      wvec: Tensor, active: Tensor, slot: Tensor) -> None:
    """Subtract Σ E_a C⁻¹ E_bᵀ from S and Σ E_a C⁻¹ w from rhs (block form, module docstring)."""
    eb = lin.eblocks
    hw = eb.shape[2]
    root = cinv.sqrt()
    scaled = eb * root[layout.block_frame].unsqueeze(1)  # E_a C^-1/2
    ew = torch.bmm(scaled, (wvec * root)[layout.block_frame].unsqueeze(2)).squeeze(2)  # (Q, 6)
    rhs.index_add_(0, slot[layout.block_node], -ew.double())
    for d, start, count in layout.groups:
        a = scaled[start:start + count * d].reshape(count, d * POSE_DOF, hw)
        prod = torch.bmm(a, a.transpose(1, 2)).reshape(count, d, POSE_DOF, d, POSE_DOF).permute(0, 1, 3, 2, 4)
        nd = layout.block_node[start:start + count * d].reshape(count, d)
        _scatter_blocks(s_blocks, nd.unsqueeze(2).expand(-1, d, d), nd.unsqueeze(1).expand(-1, d, d), -prod, active)


def edge_nodes(ii: Tensor, jj: Tensor, layout: BlockLayout) -> Tensor:
    """(E, 2 or 3): the nodes (ii, jj[, focal]) of each edge's rows."""
    nodes = [ii, jj] + ([torch.full_like(ii, layout.num_frames)] if layout.nf else [])
    return torch.stack(nodes, dim=1)


def reduced_system(lin: LinearSystem, layout: BlockLayout, ii: Tensor, jj: Tensor, cinv: Tensor | None,
                   wvec: Tensor | None, active: Tensor, num_active: int) -> tuple[Tensor, Tensor]:
    """(S (6A, 6A) float64, rhs (6A,) float64) on the active nodes (``active``: node → slot or −1)."""
    e, k = lin.grad.shape
    nb = 3 if layout.nf else 2
    dev = lin.grad.device
    hess = _pad_blocks(lin.hess, nb, 2)  # pad the focal rows to a full 6-row block
    grad = _pad_blocks(lin.grad, nb, 1)
    nodes = edge_nodes(ii, jj, layout)  # (E, nb)
    s_blocks = torch.zeros(num_active * num_active + 1, POSE_DOF, POSE_DOF, dtype=torch.float64, device=dev)  # + sink
    rhs = torch.zeros(num_active + 1, POSE_DOF, dtype=torch.float64, device=dev)  # last slot = inactive sink
    hb = hess.reshape(e, nb, POSE_DOF, nb, POSE_DOF).permute(0, 1, 3, 2, 4)
    _scatter_blocks(s_blocks, nodes.unsqueeze(2).expand(e, nb, nb), nodes.unsqueeze(1).expand(e, nb, nb), hb, active)
    slot = torch.where(active >= 0, active, num_active)
    rhs.index_add_(0, slot[nodes.reshape(-1)], grad.reshape(-1, POSE_DOF).double())
    if lin.erows is not None:
        _edge_form_schur(s_blocks, rhs, lin, ii, nodes, cinv, wvec, active, slot)
    elif lin.eblocks is not None:
        _block_form_schur(s_blocks, rhs, lin, layout, cinv, wvec, active, slot)
    s = s_blocks[:-1].reshape(num_active, num_active, POSE_DOF, POSE_DOF).permute(0, 2, 1, 3)
    return s.reshape(num_active * POSE_DOF, num_active * POSE_DOF), rhs[:num_active].reshape(-1)


def active_nodes(layout: BlockLayout, ii: Tensor, jj: Tensor, t0: int) -> tuple[Tensor, Tensor]:
    """(node → slot or −1 (M,), the active node ids (A,)): poses ≥ t0 in an edge, plus the focal node."""
    used = torch.zeros(layout.num_nodes, dtype=torch.bool, device=ii.device)
    used[ii] = True
    used[jj] = True
    used[:min(t0, layout.num_frames)] = False
    if layout.nf:
        used[layout.num_frames] = True
    ids = torch.nonzero(used).squeeze(1)
    slot = torch.full((layout.num_nodes,), -1, dtype=torch.long, device=ii.device)
    slot[ids] = torch.arange(ids.shape[0], device=ii.device)
    return slot, ids


def solve_pose_system(s: Tensor, rhs: Tensor, params: BAParams, pad_rows: Tensor | None) -> tuple[Tensor, bool]:
    """Damp, factorise (Cholesky, float64) and solve; (Δ, solved) with Δ = 0 on failure."""
    diag = s.diagonal()
    diag.add_(params.pose_damping_rel * diag + params.pose_damping_abs)
    if pad_rows is not None:
        diag[pad_rows] = 1.0
    chol, info = torch.linalg.cholesky_ex(s)
    if int(info) != 0:
        return torch.zeros_like(rhs), False
    dx = torch.cholesky_solve(rhs.unsqueeze(1), chol).squeeze(1)
    if not bool(torch.isfinite(dx).all()):
        return torch.zeros_like(rhs), False
    return dx, True


def apply_focal_update(intrinsics: Tensor, delta: Tensor, focal_mode: str) -> Tensor:
    """fx, fy after a step on the log focal lengths: 'shared' fx, fy ← ·exp(δ); 'xy' each its own."""
    out = intrinsics.clone()
    if focal_mode == "shared":
        out[0:2] = intrinsics[0:2] * torch.exp(delta[0])
    elif focal_mode == "xy":
        out[0:2] = intrinsics[0:2] * torch.exp(delta[0:2])
    return out


def solve_step(poses: Tensor, disps: Tensor, intrinsics: Tensor, depth_prior: Tensor | None, ii: Tensor, jj: Tensor,
               lin: LinearSystem, layout: BlockLayout, params: BAParams) -> tuple[Tensor, Tensor, Tensor, float, bool]:
    """One GN update from a linearisation: (poses, disps, intrinsics, cost, solved)."""
    slot, ids = active_nodes(layout, ii, jj, params.t0)
    num_active = int(ids.shape[0])
    motion_only = params.motion_only or not lin.has_depth
    cinv = wvec = None
    prior_cost = lin.cost.new_zeros(())
    if not motion_only:
        cinv, wvec, prior_cost = depth_system(lin, disps, depth_prior, params)
    cost = float(lin.cost + prior_cost)
    if num_active == 0:
        return poses, disps, intrinsics, cost, True
    s, rhs = reduced_system(lin, layout, ii, jj, cinv, wvec, slot, num_active)
    pad_rows = None
    if layout.nf:
        base = int(slot[layout.num_frames]) * POSE_DOF
        pad_rows = torch.arange(base + layout.nf, base + POSE_DOF, device=s.device)
    dx, solved = solve_pose_system(s, rhs, params, pad_rows)
    if not solved:
        return poses, disps, intrinsics, cost, False
    node_dx = torch.zeros(layout.num_nodes, POSE_DOF, dtype=poses.dtype, device=poses.device)
    node_dx[ids] = dx.reshape(num_active, POSE_DOF).to(poses.dtype)
    pose_ids = ids[ids < layout.num_frames]
    new_poses = poses.clone()
    new_poses[pose_ids] = normalize_pose(pose_compose(se3_exp(node_dx[pose_ids]), poses[pose_ids]))
    new_intr = intrinsics
    if layout.nf:
        new_intr = apply_focal_update(intrinsics, node_dx[layout.num_frames], params.optimize_focal)
    new_disps = disps
    if not motion_only:
        n, hw = cinv.shape
        if lin.erows is not None:  # (Eᵀ Δξ)_n = Σ_k e_kᵀ T_kᵀ [Δξ_i; Δξ_j; Δf]
            e, k = lin.grad.shape
            xk = node_dx[edge_nodes(ii, jj, layout)].reshape(e, -1)[:, :k]
            delta = torch.bmm(lin.tmat.transpose(1, 2), xk.unsqueeze(2).to(lin.tmat.dtype))  # (E, 6+nf, 1)
            etx = torch.bmm(delta.transpose(1, 2), lin.erows).squeeze(1)  # (E, HW)
            back = torch.zeros(n, hw, dtype=etx.dtype, device=etx.device).index_add_(0, ii, etx)
        else:
            etx = torch.bmm(node_dx[layout.block_node].unsqueeze(1), lin.eblocks).squeeze(1)  # (Q, HW)
            back = torch.zeros(n, hw, dtype=etx.dtype, device=etx.device).index_add_(0, layout.block_frame, etx)
        delta = cinv * (wvec - back)
        new_disps = (disps + delta.reshape(disps.shape)).clamp_min(params.min_disp)
    return new_poses, new_disps, new_intr, cost, True
