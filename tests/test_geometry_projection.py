"""Reprojection (Eq. 1) and its fused Jacobians against autograd, in float64."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.geometry.lie import pose_compose, se3_exp
from droidw_cli.geometry.projection import edge_jacobians, pixel_grid, project_edges, reproject

H, W = 6, 8


def _scene(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    n = 4
    xi = torch.randn(n, 6, generator=g, dtype=torch.float64) * torch.tensor([0.2, 0.2, 0.2, 0.1, 0.1, 0.1], dtype=torch.float64)
    poses = se3_exp(xi)
    disps = 0.2 + 0.6 * torch.rand(n, H, W, generator=g, dtype=torch.float64)
    intr = torch.tensor([7.0, 6.5, 3.6, 2.4], dtype=torch.float64)
    ii = torch.tensor([0, 1, 2, 3, 0, 2])
    jj = torch.tensor([1, 0, 3, 1, 2, 0])
    return poses, disps, intr, ii, jj


def _coords(poses, disps, intr, ii, jj):
    return project_edges(poses, disps, intr, ii, jj, min_depth=0.05).coords  # (E, 2, HW)


def test_reproject_identity_and_grid_convention():
    poses, disps, intr, _, _ = _scene()
    same = torch.stack([poses[0], poses[0]])
    coords, valid = reproject(same, disps[:2], intr, torch.tensor([0]), torch.tensor([1]))
    gx, gy = pixel_grid(H, W, dtype=torch.float64)
    assert torch.allclose(coords[0, ..., 0].reshape(-1), gx, atol=1e-10)
    assert torch.allclose(coords[0, ..., 1].reshape(-1), gy, atol=1e-10)
    assert bool(valid.all())


def test_reproject_matches_explicit_point_transfer():
    poses, disps, intr, ii, jj = _scene(1)
    coords, _ = reproject(poses, disps, intr, ii, jj)
    fx, fy, cx, cy = intr
    gx, gy = pixel_grid(H, W, dtype=torch.float64)
    from droidw_cli.geometry.lie import pose_act, pose_inverse
    for k in range(len(ii)):
        depth = 1.0 / disps[ii[k]].reshape(-1)
        pc = torch.stack(((gx - cx) / fx * depth, (gy - cy) / fy * depth, depth), -1)
        pw = pose_act(pose_inverse(poses[ii[k]]).expand(len(pc), 7), pc)
        pj = pose_act(poses[jj[k]].expand(len(pc), 7), pw)
        uv = torch.stack((fx * pj[:, 0] / pj[:, 2] + cx, fy * pj[:, 1] / pj[:, 2] + cy), -1)
        assert torch.allclose(coords[k].reshape(-1, 2), uv, atol=1e-9)


def test_min_depth_invalidates_points():
    poses, disps, intr, ii, jj = _scene(2)
    disps = disps.clone()
    disps[0, 0, 0] = 100.0  # depth 0.01 < 0.05
    _, valid = reproject(poses, disps, intr, ii, jj, min_depth=0.05)
    assert not bool(valid[0, 0, 0])
    assert bool(valid[0, 1, 1])


def _autograd_pose_jacobian(poses, disps, intr, ii, jj, side: str):
    """∂p_k/∂ξ for a left perturbation of edge k's own pose i (or j), one pass for all edges."""
    e = len(ii)
    ext = torch.cat((poses[ii], poses[jj]))
    ext_disps = torch.cat((disps[ii], disps[ii]))
    ei, ej = torch.arange(e), e + torch.arange(e)

    def f(xi):
        moved = pose_compose(se3_exp(xi), ext[ei] if side == "i" else ext[ej])
        p = torch.cat((moved, ext[ej])) if side == "i" else torch.cat((ext[ei], moved))
        return _coords(p, ext_disps, intr, ei, ej)

    jac = torch.autograd.functional.jacobian(f, torch.zeros(e, 6, dtype=torch.float64), vectorize=True)
    return torch.stack([jac[k, :, :, k, :] for k in range(e)])  # (E, 2, HW, 6)


@pytest.mark.parametrize("side", ["i", "j"])
def test_pose_jacobians_match_autograd(side):
    poses, disps, intr, ii, jj = _scene(3)
    proj = project_edges(poses, disps, intr, ii, jj, 0.05)
    jac, _ = edge_jacobians(proj, intr)
    rows = slice(0, 6) if side == "i" else slice(6, 12)
    ours = jac[:, rows].permute(0, 2, 3, 1)  # (E, 2, HW, 6)
    ref = _autograd_pose_jacobian(poses, disps, intr, ii, jj, side)
    assert torch.allclose(ours, ref, atol=1e-8, rtol=1e-6)


def test_disparity_jacobian_matches_autograd():
    poses, disps, intr, ii, jj = _scene(4)
    proj = project_edges(poses, disps, intr, ii, jj, 0.05)
    _, jac_d = edge_jacobians(proj, intr)
    d = disps.clone().requires_grad_(True)
    c = _coords(poses, d, intr, ii, jj)
    for comp in range(2):
        g, = torch.autograd.grad(c[:, comp].sum(), d, retain_graph=True)
        # each pixel of frame ii[k] only influences edge k's own coordinate; sum over edges with same ii
        expect = torch.zeros_like(disps).reshape(len(disps), -1)
        expect.index_add_(0, ii, jac_d[:, comp])
        assert torch.allclose(g.reshape(len(disps), -1), expect, atol=1e-9)


@pytest.mark.parametrize("mode", ["xy", "shared"])
def test_focal_jacobian_matches_autograd(mode):
    poses, disps, intr, ii, jj = _scene(5)
    proj = project_edges(poses, disps, intr, ii, jj, 0.05)
    jac, _ = edge_jacobians(proj, intr, mode)
    def f(delta):
        scale = torch.exp(delta) if mode == "xy" else torch.exp(delta).expand(2)
        k = intr * torch.cat((scale, torch.ones(2, dtype=delta.dtype)))
        return _coords(poses, disps, k, ii, jj)
    nf = 2 if mode == "xy" else 1
    ref = torch.autograd.functional.jacobian(f, torch.zeros(nf, dtype=torch.float64))  # (E, 2, HW, nf)
    ours = jac[:, 12:].permute(0, 2, 3, 1)
    assert ours.shape == ref.shape
    assert torch.allclose(ours, ref, atol=1e-8, rtol=1e-6)


def test_bilinear_sampling_matches_grid_sample_align_corners():
    from droidw_cli.geometry.sampling import inside_image, sample_maps
    g = torch.Generator().manual_seed(7)
    maps = torch.rand(3, H, W, generator=g, dtype=torch.float64)
    x = torch.rand(2, 50, generator=g, dtype=torch.float64) * (W + 2) - 1.0
    y = torch.rand(2, 50, generator=g, dtype=torch.float64) * (H + 2) - 1.0
    x[0, 0], y[0, 0] = W - 1.0, H - 1.0  # exact last pixel
    frame = torch.tensor([2, 0])
    ours = sample_maps(maps, frame, x, y)
    grid = torch.stack((2 * x / (W - 1) - 1, 2 * y / (H - 1) - 1), -1).unsqueeze(1)  # (2, 1, 50, 2)
    ref = torch.nn.functional.grid_sample(maps[frame].unsqueeze(1), grid, mode="bilinear",
                                          padding_mode="border", align_corners=True)[:, 0, 0]
    assert torch.allclose(ours, ref, atol=1e-10)
    inside = inside_image(x, y, H, W)
    assert bool(inside[0, 0]) and not bool(inside[(x < 0)].any())
