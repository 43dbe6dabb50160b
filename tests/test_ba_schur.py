"""The block-sparse Schur solve against a dense normal-equation reference (float64)."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.schur import LinearSystem, build_layout, solve_step
from droidw_cli.geometry.lie import pose_compose, se3_exp
from droidw_cli.geometry.projection import FOCAL_DOF, edge_jacobians, project_edges
from droidw_backend_cpu.linearize import linearize, scatter_eblocks

H, W = 5, 7


def _problem(seed=0):
    g = torch.Generator().manual_seed(seed)
    n = 5
    xi = torch.randn(n, 6, generator=g, dtype=torch.float64) * 0.05
    xi[:, 0] += torch.arange(n) * 0.1
    poses = se3_exp(xi)
    disps = 0.3 + 0.4 * torch.rand(n, H, W, generator=g, dtype=torch.float64)
    intr = torch.tensor([6.0, 5.5, 3.1, 2.2], dtype=torch.float64)
    ii = torch.tensor([0, 1, 1, 2, 3, 4, 0, 2, 4, 3])
    jj = torch.tensor([1, 0, 2, 1, 4, 3, 2, 4, 2, 1])
    e = len(ii)
    target = project_edges(poses, disps, intr, ii, jj, 0.05).coords.reshape(e, 2, H, W).permute(0, 2, 3, 1)
    target = target + 0.3 * torch.randn(target.shape, generator=g, dtype=torch.float64)
    weight = torch.rand(e, H, W, 2, generator=g, dtype=torch.float64)
    prior = torch.where(torch.rand(n, H, W, generator=g, dtype=torch.float64) > 0.5, disps * 1.1, torch.zeros_like(disps))
    return poses, disps, intr, ii, jj, target, weight, prior


def _dense_step(poses, disps, intr, ii, jj, target, weight, prior, params):
    """Dense GN step: full J over [ξ_0..ξ_{N−1}, focal, d], Schur with dense matrices."""
    n = poses.shape[0]
    hw = H * W
    e = len(ii)
    nf = FOCAL_DOF[params.optimize_focal]
    proj = project_edges(poses, disps, intr, ii, jj, params.min_depth)
    jac, jac_d = edge_jacobians(proj, intr, params.optimize_focal)
    res = target.permute(0, 3, 1, 2).reshape(e, 2, hw) - proj.coords
    w = weight.permute(0, 3, 1, 2).reshape(e, 2, hw) * params.flow_weight_scale * proj.valid.unsqueeze(1)
    npose = 6 * n + nf
    J = torch.zeros(e, 2, hw, npose + n * hw, dtype=torch.float64)
    for k in range(e):  # small reference: loops are fine here
        J[k, :, :, 6 * ii[k]:6 * ii[k] + 6] += jac[k, :6].permute(1, 2, 0)
        J[k, :, :, 6 * jj[k]:6 * jj[k] + 6] += jac[k, 6:12].permute(1, 2, 0)
        if nf:
            J[k, :, :, 6 * n:6 * n + nf] += jac[k, 12:].permute(1, 2, 0)
        for p in range(hw):
            J[k, :, p, npose + ii[k] * hw + p] = jac_d[k, :, p]
    J = J.reshape(-1, npose + n * hw)
    wf, rf = w.reshape(-1), res.reshape(-1)
    Hm = J.T @ (wf.unsqueeze(1) * J)
    g = J.T @ (wf * rf)
    dflat = disps.reshape(-1)
    pf = prior.reshape(-1)
    has = pf > 0
    dd = slice(npose, None)
    cdiag = Hm[dd, dd].diagonal() + params.gamma_depth * has + torch.where(has, params.prior_damping, params.depth_damping)
    gd = g[dd] + params.gamma_depth * has * (pf - dflat)
    off = Hm[dd, dd] - torch.diag(Hm[dd, dd].diagonal())
    assert float(off.abs().max()) == 0.0  # C really is diagonal
    used = torch.zeros(n, dtype=torch.bool)
    used[ii] = True
    used[jj] = True
    used[:params.t0] = False
    cols = [6 * i + c for i in range(n) if used[i] for c in range(6)] + list(range(6 * n, 6 * n + nf))
    cols = torch.tensor(cols)
    B = Hm[cols][:, cols]
    E = Hm[cols][:, dd]
    S = B - E @ (E / cdiag).T
    rhs = g[cols] - E @ (gd / cdiag)
    S = S + torch.diag(params.pose_damping_rel * S.diagonal() + params.pose_damping_abs)
    dx = torch.linalg.solve(S, rhs)
    ddisp = (gd - E.T @ dx) / cdiag
    full = torch.zeros(npose, dtype=torch.float64)
    full[cols] = dx
    new_poses = pose_compose(se3_exp(full[:6 * n].reshape(n, 6)), poses)
    return new_poses, (dflat + ddisp).reshape(disps.shape), full[6 * n:]


@pytest.mark.parametrize("focal", ["none", "shared", "xy"])
@pytest.mark.parametrize("t0", [1, 2])
def test_block_sparse_step_equals_dense_reference(focal, t0):
    poses, disps, intr, ii, jj, target, weight, prior = _problem()
    params = BAParams(t0=t0, optimize_focal=focal, gamma_depth=0.01, min_disp=1e-6,
                      uncertainty=UncertaintyParams(enable=False))
    layout = build_layout(ii, jj, 5, focal)
    lin = linearize(poses, disps, intr, ii, jj, target, weight, None, params, layout)
    new_poses, new_disps, new_intr, cost, solved = solve_step(poses, disps, intr, prior, ii, jj, lin, layout, params)
    ref_poses, ref_disps, ref_focal = _dense_step(poses, disps, intr, ii, jj, target, weight, prior, params)
    assert solved
    assert torch.allclose(new_poses, ref_poses, atol=1e-9)
    assert torch.allclose(new_disps, ref_disps.clamp_min(params.min_disp), atol=1e-9)
    assert torch.equal(new_poses[:t0], poses[:t0])
    if focal == "xy":
        assert torch.allclose(new_intr[:2], intr[:2] * torch.exp(ref_focal), atol=1e-9)
    elif focal == "shared":
        assert torch.allclose(new_intr[:2], intr[:2] * torch.exp(ref_focal[0]), atol=1e-9)
        assert torch.allclose(new_intr[1] / new_intr[0], intr[1] / intr[0])
    assert torch.equal(new_intr[2:], intr[2:])
    assert cost > 0


@pytest.mark.parametrize("focal", ["none", "xy"])
def test_block_form_equals_edge_form(focal):
    """E handed over in block form (as the CUDA backend does) gives the edge form's step."""
    poses, disps, intr, ii, jj, target, weight, prior = _problem(3)
    params = BAParams(t0=1, optimize_focal=focal, gamma_depth=0.01, min_disp=1e-6,
                      uncertainty=UncertaintyParams(enable=False))
    layout = build_layout(ii, jj, 5, focal)
    lin = linearize(poses, disps, intr, ii, jj, target, weight, None, params, layout)
    assert lin.erows is not None and lin.eblocks is None
    eblocks = torch.zeros(layout.num_blocks, 6, H * W, dtype=torch.float64)
    scatter_eblocks(eblocks, layout.edge_blocks, lin.tmat, lin.erows)
    block = LinearSystem(lin.hess, lin.grad, eblocks, lin.cdiag, lin.wvec, lin.cost)
    edge_step = solve_step(poses, disps, intr, prior, ii, jj, lin, layout, params)
    block_step = solve_step(poses, disps, intr, prior, ii, jj, block, layout, params)
    for a, b in zip(edge_step[:3], block_step[:3]):
        assert torch.allclose(a, b, atol=1e-10)
    assert edge_step[3] == pytest.approx(block_step[3])


def test_motion_only_keeps_disparities_and_uses_pose_block():
    poses, disps, intr, ii, jj, target, weight, _ = _problem(1)
    params = BAParams(motion_only=True, uncertainty=UncertaintyParams(enable=False))
    layout = build_layout(ii, jj, 5)
    lin = linearize(poses, disps, intr, ii, jj, target, weight, None, params, layout)
    assert lin.eblocks is None
    new_poses, new_disps, _, _, solved = solve_step(poses, disps, intr, None, ii, jj, lin, layout, params)
    assert solved and torch.equal(new_disps, disps)
    assert not torch.allclose(new_poses[1:], poses[1:])


def test_failed_cholesky_gives_zero_step_not_nan():
    poses, disps, intr, ii, jj, *_ = _problem(2)
    e, hw = len(ii), H * W
    layout = build_layout(ii, jj, 5)
    lin = LinearSystem(hess=-1e6 * torch.eye(12, dtype=torch.float64).expand(e, 12, 12).clone(),
                       grad=torch.ones(e, 12, dtype=torch.float64), eblocks=None, cdiag=None, wvec=None,
                       cost=torch.tensor(1.0, dtype=torch.float64))
    new_poses, new_disps, _, cost, solved = solve_step(poses, disps, intr, None, ii, jj, lin, layout,
                                                        BAParams(motion_only=True))
    assert not solved
    assert torch.equal(new_poses, poses) and torch.equal(new_disps, disps)
    assert cost == 1.0


def test_layout_groups_blocks_by_frame():
    ii = torch.tensor([0, 0, 0, 1, 2, 2])
    jj = torch.tensor([1, 2, 3, 0, 0, 3])
    layout = build_layout(ii, jj, 4)
    # frame 0: nodes {0,1,2,3}; frame 1: {1,0}; frame 2: {2,0,3}
    assert layout.num_blocks == 9
    for k in range(len(ii)):
        bi, bj = layout.edge_blocks[k].tolist()
        assert layout.block_frame[bi] == ii[k] and layout.block_node[bi] == ii[k]
        assert layout.block_frame[bj] == ii[k] and layout.block_node[bj] == jj[k]
    for d, start, count in layout.groups:
        frames = layout.block_frame[start:start + d * count].reshape(count, d)
        assert bool((frames == frames[:, :1]).all())
