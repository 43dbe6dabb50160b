"""Gauss-Newton convergence on synthetic scenes with exact targets (CPU backend)."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.synthetic import make_problem, max_pose_error, perturb
from droidw_cli.geometry.lie import pose_inverse
from droidw_backend_cpu import CpuBackend

pytestmark = pytest.mark.usefixtures("one_torch_thread")

PLAIN = UncertaintyParams(enable=False)


@pytest.fixture(scope="module")
def problem():
    prob = make_problem(12, h=48, w=64, radius=3, seed=0)
    assert 30 <= prob.edges.num_edges <= 60
    depth = 1.0 / prob.truth.disps
    assert 1.0 <= float(depth.min()) and float(depth.max()) <= 5.0
    return prob


def _observed(prob) -> torch.Tensor:
    """Pixels seen by at least one edge with positive weight (the others are unobservable)."""
    n, h, w = prob.truth.disps.shape
    seen = torch.zeros(n, h * w).index_add_(0, prob.edges.ii, prob.edges.weight[..., 0].reshape(len(prob.edges.ii), -1))
    return seen.reshape(n, h, w) > 0


def _run(state, edges, params, iters=20):
    backend = CpuBackend()
    costs = []
    for _ in range(iters):
        res = backend.ba_step(state, edges, params)
        assert res.solved
        costs.append(res.cost)
        state = res.state
    return state, costs


def _rel_disp_error(est, truth, mask):
    return float(((est - truth).abs() / truth)[mask].max())


def test_converges_with_two_fixed_poses(problem):
    start = perturb(problem.truth, trans=0.04, rot_deg=3.0, disp_rel=0.2, fixed=2, seed=1)
    assert max_pose_error(start.poses, problem.truth.poses)[0] > 0.02
    st, costs = _run(start, problem.edges, BAParams(t0=2, uncertainty=PLAIN))
    et, er = max_pose_error(st.poses, problem.truth.poses)
    assert et < 1e-3 and er < 1e-3
    assert _rel_disp_error(st.disps, problem.truth.disps, _observed(problem)) < 1e-3
    assert costs[-1] < 1e-6 * costs[0]
    assert torch.equal(st.poses[:2], start.poses[:2])


def test_converges_up_to_scale_with_one_fixed_pose(problem):
    start = perturb(problem.truth, trans=0.04, rot_deg=3.0, disp_rel=0.2, fixed=1, seed=2)
    st, _ = _run(start, problem.edges, BAParams(t0=1, uncertainty=PLAIN))
    # monocular gauge: frame 0 fixed, global scale free -> align the scale on camera centres
    ce = pose_inverse(st.poses.double())[:, :3]
    ct = pose_inverse(problem.truth.poses.double())[:, :3]
    s = float(((ce - ce[0]) * (ct - ct[0])).sum() / ((ce - ce[0]) ** 2).sum())
    scaled = torch.cat((st.poses[:, :3] * s, st.poses[:, 3:]), dim=1)
    et, er = max_pose_error(scaled, problem.truth.poses)
    assert et < 1e-3 and er < 1e-3
    assert _rel_disp_error(st.disps / s, problem.truth.disps, _observed(problem)) < 1e-3


def test_depth_prior_fixes_the_scale(problem):
    start = perturb(problem.truth, trans=0.04, rot_deg=3.0, disp_rel=0.2, fixed=1, seed=3)
    start = start.with_(depth_prior=problem.truth.disps.clone())
    st, _ = _run(start, problem.edges, BAParams(t0=1, gamma_depth=0.01, uncertainty=PLAIN), iters=15)
    et, er = max_pose_error(st.poses, problem.truth.poses)
    assert et < 1e-3 and er < 1e-3


def test_motion_only_moves_poses_only(problem):
    start = perturb(problem.truth, trans=0.03, rot_deg=2.0, disp_rel=0.0, fixed=1, seed=4)
    st, _ = _run(start, problem.edges, BAParams(t0=1, motion_only=True, uncertainty=PLAIN), iters=8)
    assert torch.equal(st.disps, start.disps)
    et, er = max_pose_error(st.poses, problem.truth.poses)
    assert et < 1e-3 and er < 1e-3


@pytest.mark.parametrize("mode", ["shared", "xy"])
def test_focal_self_calibration(problem, mode):
    start = perturb(problem.truth, trans=0.02, rot_deg=1.0, disp_rel=0.1, fixed=2, seed=5)
    wrong = problem.truth.intrinsics.clone()
    wrong[:2] *= torch.tensor([1.04, 0.97]) if mode == "xy" else 1.04
    st, _ = _run(start.with_(intrinsics=wrong), problem.edges, BAParams(t0=2, optimize_focal=mode, uncertainty=PLAIN),
                 iters=20)
    rel = (st.intrinsics[:2] - problem.truth.intrinsics[:2]).abs() / problem.truth.intrinsics[:2]
    assert float(rel.max()) < 1e-3
    assert torch.equal(st.intrinsics[2:], wrong[2:])
    assert max_pose_error(st.poses, problem.truth.poses)[0] < 1e-3


@pytest.mark.parametrize("mode,bidirectional", [("clamp", True), ("inverse", False), ("inverse", True)])
def test_uncertainty_weighting_keeps_exact_solution(problem, mode, bidirectional):
    """With exact targets any positive weighting still converges to the truth."""
    start = perturb(problem.truth, trans=0.03, rot_deg=2.0, disp_rel=0.2, fixed=2, seed=6)
    g = torch.Generator().manual_seed(0)
    theta = 0.5 * torch.randn(start.theta.shape, generator=g)
    params = BAParams(t0=2, uncertainty=UncertaintyParams(mode=mode, bidirectional=bidirectional))
    st, _ = _run(start.with_(theta=theta), problem.edges, params, iters=15)
    assert max_pose_error(st.poses, problem.truth.poses)[0] < 1e-3
