"""Native/CPU parity: the C++ backend must agree with the torch reference (skipped where it cannot be built).

The shared BA cases (``ba_cases.BA_STEP_CASES``) on the CUDA parity test's
problem.  The ``ba_step`` update is compared at 1e-5 relative with the torch
reference run in float64 (the same code, :func:`droidw_backend_cpu.linearize.linearize`
and :func:`droidw_cli.ba.schur.solve_step`), and at 1e-4 with the float32 CPU
backend: the latter's own float32 sums move its step by up to 5e-5 of its size
on this problem (the native backend sums pixels in float64 beyond tiles of 64,
and lands 10x closer to the float64 step).  ``uncertainty_step`` and
``reproject`` are compared with the CPU backend at 1e-5 and 1e-6.
"""

from __future__ import annotations

import pytest
import torch

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.schur import build_layout, solve_step
from droidw_cli.ba.synthetic import make_problem, perturb
from droidw_backend_cpu import CpuBackend
from droidw_backend_cpu.linearize import linearize
from ba_cases import BA_STEP_CASES

REL = 1e-5
REL_FLOAT32_REFERENCE = 1e-4


@pytest.fixture(scope="module")
def backends():
    from droidw_backend_native import NativeBackend, build

    try:
        NativeBackend.ensure_built()
    except build.KernelBuildError as exc:
        pytest.skip(f"the native kernels cannot be built here: {exc}")
    return CpuBackend(), NativeBackend()


@pytest.fixture(scope="module")
def problem():
    prob = make_problem(10, radius=3, movers=True, mover_frames=(5, 6, 7, 8, 9), channels=16, seed=2)
    g = torch.Generator().manual_seed(3)
    start = perturb(prob.truth, trans=0.02, rot_deg=2.0, disp_rel=0.1, seed=4)
    state = start.with_(theta=0.3 * torch.randn(17, generator=g))
    prior = torch.where(torch.rand(state.disps.shape, generator=torch.Generator().manual_seed(0)) > 0.5,
                        state.disps * 1.05, torch.zeros_like(state.disps))
    return state, prob.edges, prior


def _close(a, b, rel):
    a, b = a.detach().double(), b.detach().double()
    scale = float(b.abs().max()) or 1.0
    return float((a - b).abs().max()) <= rel * scale


def _float64_step(cpu, state, edges, params):
    """(poses, disps, intrinsics, cost) of the torch reference's step computed in float64."""
    d = lambda t: None if t is None else t.double()  # noqa: E731
    u_map = cpu.uncertainty_weights(state, params)
    layout = build_layout(edges.ii, edges.jj, state.num_frames, params.optimize_focal)
    lin = linearize(d(state.poses), d(state.disps), d(state.intrinsics), edges.ii, edges.jj, d(edges.target),
                    d(edges.weight), d(u_map), params, layout)
    poses, disps, intr, cost, solved = solve_step(d(state.poses), d(state.disps), d(state.intrinsics),
                                                  d(state.depth_prior), edges.ii, edges.jj, lin, layout, params)
    assert solved
    return poses, disps, intr, cost


def test_reproject_equal(backends, problem):
    cpu, native = backends
    state, edges, _ = problem
    c1, v1 = cpu.reproject(state, edges.ii, edges.jj)
    c2, v2 = native.reproject(state, edges.ii, edges.jj)
    assert c2.shape == c1.shape and c2.dtype == c1.dtype
    assert _close(c2, c1, 1e-6)
    assert torch.equal(v1, v2)


@pytest.mark.parametrize("params", BA_STEP_CASES)
def test_ba_step_equal(backends, problem, params):
    cpu, native = backends
    state, edges, prior = problem
    state = state.with_(depth_prior=prior)
    r1 = cpu.ba_step(state, edges, params)
    r2 = native.ba_step(state, edges, params)
    assert r1.solved and r2.solved
    assert r1.cost == pytest.approx(r2.cost, rel=REL)
    poses, disps, intr, cost = _float64_step(cpu, state, edges, params)
    assert r2.cost == pytest.approx(cost, rel=REL)
    # the updates (not the states), to 1e-5 of the float64 step and 1e-4 of the float32 reference's
    for rel, (p, d, f) in ((REL, (poses, disps, intr)),
                           (REL_FLOAT32_REFERENCE, (r1.state.poses, r1.state.disps, r1.state.intrinsics))):
        assert _close(r2.state.poses - state.poses, p - state.poses, rel)
        assert _close(r2.state.disps - state.disps, d - state.disps, rel)
        assert _close(r2.state.intrinsics - state.intrinsics, f - state.intrinsics, rel)


@pytest.mark.parametrize("per_keyframe", [True, False])
@pytest.mark.parametrize("geo_sigma", [0.0, 1.0])
def test_uncertainty_step_equal(backends, problem, per_keyframe, geo_sigma):
    cpu, native = backends
    state, edges, _ = problem
    params = BAParams(uncertainty=UncertaintyParams(average_per_keyframe=per_keyframe, geo_sigma=geo_sigma))
    r1 = cpu.uncertainty_step(state, edges, params)
    r2 = native.uncertainty_step(state, edges, params)
    assert r1.loss == pytest.approx(r2.loss, rel=REL)
    assert _close(r2.theta - state.theta, r1.theta - state.theta, REL)


def test_same_result_run_to_run_and_for_any_thread_count(backends, problem):
    """Fixed-order sums: bit-identical GN steps and E_uncer on 1 and 2 threads, and on a repeat."""
    _, native = backends
    state, edges, prior = problem
    state = state.with_(depth_prior=prior)
    params = BAParams(uncertainty=UncertaintyParams(mode="relative", bidirectional=True, geo_sigma=1.0))
    before = torch.get_num_threads()
    runs = []
    try:
        for threads in (1, 2, 2):
            torch.set_num_threads(threads)
            step = native.ba_step(state, edges, params)
            unc = native.uncertainty_step(state, edges, params)
            runs.append((step.state.poses, step.state.disps, step.cost, unc.theta, unc.loss))
    finally:
        torch.set_num_threads(before)
    for other in runs[1:]:
        assert torch.equal(other[0], runs[0][0]) and torch.equal(other[1], runs[0][1])
        assert other[2] == runs[0][2] and other[4] == runs[0][4]
    # θ also goes through torch's (MKL's) Σ G·du/da·F, whose summation order follows the thread count
    assert torch.equal(runs[2][3], runs[1][3])
    assert _close(runs[1][3] - state.theta, runs[0][3] - state.theta, 1e-6)


def test_strided_edges_read_in_place(backends, problem):
    """target and weight may be views (the kernel reads their strides): same step as from contiguous copies."""
    _, native = backends
    state, edges, _ = problem
    assert not edges.target.is_contiguous()  # the synthetic targets are views
    dense = type(edges)(edges.ii, edges.jj, edges.target.contiguous(), edges.weight.contiguous())
    a = native.ba_step(state, edges, BAParams())
    b = native.ba_step(state, dense, BAParams())
    assert torch.equal(a.state.poses, b.state.poses) and torch.equal(a.state.disps, b.state.disps)
