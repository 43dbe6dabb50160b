"""The CUDA backend's Python side, on the CPU, with a torch stand-in for the kernels (no GPU needed).

:class:`TorchKernels` returns what ``csrc/linearize.cu`` returns — the per-edge
pose-j (and focal) Hessian blocks, gradients and cost summed in float64, the
float32 E rows, C and w — computed by the CPU backend's linearisation on a
problem of 2E frames: frame 2k is the identity with the disparity of ii[k],
frame 2k + 1 is G_ij of edge k, so that edge k of the kernel's inputs is edge
(2k, 2k + 1) there.  ``CudaBackend(device="cpu")`` then runs its own assembly
(float64 H = T H_j Tᵀ, edge-form E, float64 Schur Grams) and the shared solve.

This checks the contract between the kernels and ``backend.py`` (shapes,
dtypes, the edge form) and that a step assembled from float64 sums agrees with
the CPU backend at the parity test's 1e-4 (the real kernels: test_backends_cuda_parity.py).
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import pypose as pp
import pytest
import torch

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.synthetic import make_problem, perturb
from droidw_backend_cpu import CpuBackend
from droidw_backend_cpu.linearize import linearize
from droidw_backend_cuda import backend as cuda_backend
from ba_cases import BA_STEP_CASES

REL = 1e-4
MODES = {0: "clamp", 1: "clamp", 2: "inverse"}  # the kernel's codes (u already rescaled for "relative")
FOCAL = {0: "none", 1: "shared", 2: "xy"}


class TorchKernels:
    """The kernel module's interface (csrc/droidw_ba.cpp), computed with torch on the CPU."""

    LinearizeConfig = SimpleNamespace
    LinearizeInputs = SimpleNamespace

    def __init__(self) -> None:
        self.calls = 0

    @staticmethod
    def _params(cfg) -> BAParams:
        unc = UncertaintyParams(mode=MODES[cfg.uncertainty_mode], bidirectional=cfg.bidirectional)
        return BAParams(flow_weight_scale=cfg.flow_weight_scale, min_depth=cfg.min_depth, uncertainty=unc,
                        optimize_focal=FOCAL[cfg.focal_mode], motion_only=not cfg.with_depth)

    def linearize(self, cfg, inputs):
        self.calls += 1
        e = inputs.ii.shape[0]
        n, h, w = inputs.disps.shape
        rot, trans = inputs.rel[:, :9].reshape(e, 3, 3), inputs.rel[:, 9:]
        quat = pp.mat2SO3(rot.double(), check=False).tensor().float()
        ident = torch.zeros(e, 7)
        ident[:, 6] = 1.0
        poses = torch.stack([ident, torch.cat([trans, quat], 1)], 1).reshape(2 * e, 7)
        frames = torch.stack([inputs.ii, inputs.jj], 1).reshape(-1)
        disps = inputs.disps[frames]
        umap = getattr(inputs, "umap", None)
        umap = None if umap is None else umap[frames]
        ii2 = torch.arange(0, 2 * e, 2)
        intr = torch.tensor([cfg.fx, cfg.fy, cfg.cx, cfg.cy])
        params = self._params(cfg)

        def run(dtype):
            cast = (lambda t: None if t is None else t.to(dtype))
            return linearize(cast(poses), cast(disps), cast(intr), ii2, ii2 + 1,
                             cast(inputs.target.reshape(e, h, w, 2)), cast(inputs.weight.reshape(e, h, w, 2)),
                             cast(umap), params)

        exact, single = run(torch.float64), run(torch.float32)
        hess_j, grad_j = exact.hess[:, 6:, 6:].contiguous(), exact.grad[:, 6:].contiguous()  # T = [[−Adᵀ], [I]]
        if not cfg.with_depth:
            return hess_j, grad_j, None, None, None, exact.cost.reshape(1)
        cdiag = torch.zeros(n, h * w, dtype=torch.float64).index_add_(0, inputs.ii, single.cdiag[0::2].double())
        wvec = torch.zeros(n, h * w, dtype=torch.float64).index_add_(0, inputs.ii, single.wvec[0::2].double())
        return hess_j, grad_j, single.erows, cdiag.float(), wvec.float(), exact.cost.reshape(1)


@pytest.fixture(scope="module")
def problem():
    prob = make_problem(10, radius=3, movers=True, mover_frames=(5, 6, 7, 8, 9), channels=16, seed=2)
    g = torch.Generator().manual_seed(3)
    start = perturb(prob.truth, trans=0.02, rot_deg=2.0, disp_rel=0.1, seed=4)
    prior = torch.where(torch.rand(start.disps.shape, generator=torch.Generator().manual_seed(0)) > 0.5,
                        start.disps * 1.05, torch.zeros_like(start.disps))
    return start.with_(theta=0.3 * torch.randn(17, generator=g), depth_prior=prior), prob.edges


@pytest.fixture
def kernels(monkeypatch):
    k = TorchKernels()
    monkeypatch.setattr(cuda_backend.build, "load_kernels", lambda verbose=False: k)
    return k


def _close(a, b, rel=REL):
    a, b = a.detach().double(), b.detach().double()
    scale = float(b.abs().max()) or 1.0
    return float((a - b).abs().max()) <= rel * scale


@pytest.mark.parametrize("params", BA_STEP_CASES)
def test_cuda_assembly_matches_cpu(problem, kernels, params):
    state, edges = problem
    cpu, cuda = CpuBackend(), cuda_backend.CudaBackend(device="cpu")
    r1 = cpu.ba_step(state, edges, params)
    r2 = cuda.ba_step(state, edges, params)
    assert kernels.calls == 1
    assert r1.solved and r2.solved
    assert r2.state.poses.dtype == r2.state.disps.dtype == r2.state.intrinsics.dtype == torch.float32
    assert r1.cost == pytest.approx(r2.cost, rel=REL)
    assert _close(r2.state.poses - state.poses, r1.state.poses - state.poses)
    assert _close(r2.state.disps - state.disps, r1.state.disps - state.disps)
    # the focal step (a change of about 1/3 here) to the same 1e-4 of its size
    assert _close(r2.state.intrinsics - state.intrinsics, r1.state.intrinsics - state.intrinsics)


def test_linear_system_is_float64_edge_form(problem, kernels):
    state, edges = problem
    cuda = cuda_backend.CudaBackend(device="cpu")
    st, ed = cuda._prepare(state, edges)
    params = dataclasses.replace(BAParams(), optimize_focal="xy")
    from droidw_cli.ba.schur import build_layout

    lin = cuda._linearize(st, ed, cuda.uncertainty_weights(st, params), params,
                          build_layout(ed.ii, ed.jj, st.num_frames, "xy"))
    e = ed.num_edges
    assert lin.eblocks is None and lin.gram_dtype == torch.float64
    assert lin.hess.dtype == lin.grad.dtype == lin.cost.dtype == torch.float64
    assert lin.hess.shape == (e, 14, 14) and lin.erows.shape == (e, 8, st.grid[0] * st.grid[1])
    assert lin.tmat.dtype == lin.erows.dtype == lin.cdiag.dtype == torch.float32
