"""SE(3) helpers against pypose and against their defining identities."""

from __future__ import annotations

import pypose as pp
import torch

from droidw_cli.geometry.lie import (
    adjoint_matrix,
    pose_act,
    pose_compose,
    pose_distance,
    pose_inverse,
    pose_matrix,
    quat_to_matrix,
    se3_exp,
    se3_log,
)


def _twists(n=16, seed=0, scale=1.0):
    g = torch.Generator().manual_seed(seed)
    xi = torch.randn(n, 6, generator=g, dtype=torch.float64) * scale
    xi[0] = 0.0
    xi[1, 3:] = 1e-9  # tiny rotation: Taylor branch
    return xi


def test_se3_exp_matches_pypose_twist_order_v_then_omega():
    xi = _twists()
    ours = se3_exp(xi)
    ref = pp.se3(xi).Exp().tensor()
    # q and −q are the same rotation
    sign = torch.sign((ours[:, 3:] * ref[:, 3:]).sum(-1, keepdim=True))
    assert torch.allclose(ours[:, :3], ref[:, :3], atol=1e-10)
    assert torch.allclose(ours[:, 3:], sign * ref[:, 3:], atol=1e-10)


def test_compose_inverse_act_match_pypose():
    a, b = se3_exp(_twists(seed=1)), se3_exp(_twists(seed=2))
    x = torch.randn(16, 3, dtype=torch.float64)
    assert torch.allclose(pose_act(pose_compose(a, b), x), (pp.SE3(a) * pp.SE3(b)).Act(x), atol=1e-10)
    assert torch.allclose(pose_act(pose_inverse(a), x), pp.SE3(a).Inv().Act(x), atol=1e-10)
    r, t = pose_matrix(a)
    assert torch.allclose(r @ x.unsqueeze(-1) + t.unsqueeze(-1), pose_act(a, x).unsqueeze(-1), atol=1e-10)
    assert torch.allclose(quat_to_matrix(a[:, 3:]) @ quat_to_matrix(a[:, 3:]).transpose(1, 2),
                          torch.eye(3, dtype=torch.float64).expand(16, 3, 3), atol=1e-10)


def test_adjoint_identity():
    """Exp(Ad(T) ξ) = T Exp(ξ) T⁻¹ in the [v, ω] ordering."""
    t = se3_exp(_twists(seed=3))
    xi = _twists(seed=4, scale=0.3)
    r, tr = pose_matrix(t)
    lhs = se3_exp((adjoint_matrix(r, tr) @ xi.unsqueeze(-1)).squeeze(-1))
    rhs = pose_compose(pose_compose(t, se3_exp(xi)), pose_inverse(t))
    dt, dr = pose_distance(lhs, rhs)
    assert float(dt.max()) < 1e-9 and float(dr.max()) < 1e-9


def test_pose_distance_zero_and_positive():
    a = se3_exp(_twists(seed=5))
    dt, dr = pose_distance(a, a)
    assert float(dt.max()) < 1e-12 and float(dr.max()) < 1e-6
    b = pose_compose(se3_exp(torch.tensor([[0.1, 0, 0, 0, 0, 0.2]], dtype=torch.float64)).expand(16, 7), a)
    dt, dr = pose_distance(b, a)
    assert torch.allclose(dr, torch.full_like(dr, 0.2), atol=1e-9)


def _within_pi(xi):
    """Twists whose rotation angle is below π (where Log inverts Exp), some near 0 and near π."""
    xi = xi.clone()
    norm = xi[:, 3:].norm(dim=-1, keepdim=True).clamp(min=1e-30)
    xi[:, 3:] = torch.where(norm > 3.0, xi[:, 3:] / norm * 3.0, xi[:, 3:])
    xi[2, 3:] = torch.tensor([0.0, 0.0, 3.14])  # near π
    xi[3, 3:] = torch.tensor([3e-3, -2e-3, 1e-3])  # small: series branch of V⁻¹
    return xi


def test_se3_log_inverts_exp_and_matches_pypose():
    xi = _within_pi(_twists(seed=6))
    assert torch.allclose(se3_log(se3_exp(xi)), xi, atol=1e-9)
    poses = se3_exp(xi)
    assert torch.allclose(se3_log(poses), pp.SE3(poses).Log().tensor(), atol=1e-9)
    # −q is the same rotation: the same twist
    flipped = torch.cat((poses[:, :3], -poses[:, 3:]), dim=-1)
    assert torch.allclose(se3_log(flipped), xi, atol=1e-9)


def test_se3_log_float32_close_to_float64():
    xi = _within_pi(_twists(seed=7, scale=0.5))
    ours = se3_log(se3_exp(xi).float())
    assert ours.dtype == torch.float32
    assert torch.allclose(ours.double(), xi, atol=2e-5)
