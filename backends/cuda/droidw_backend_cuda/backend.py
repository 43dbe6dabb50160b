"""CUDA backend: the CPU backend's assembly and solve, with the hot paths as kernels.

:class:`CudaBackend` subclasses :class:`droidw_backend_cpu.CpuBackend` (all the
torch glue — block layout, Schur complement, Cholesky, updates, the θ step —
is device-agnostic and runs on the GPU as is) and replaces

* ``_linearize``: residuals, weights, Jacobians, per-edge Hessian blocks and E
  rows in one kernel (``csrc/linearize.cu``);
* ``_similarity_term``: the uncertainty data term and its ∂/∂u map
  (``csrc/similarity.cu``).

Precision.  The linearisation hands the shared solve the *edge form* of E, as the
CPU backend does: per-edge rows e_k (float32, per pixel) and T_k = [[−Ad(G_ij)ᵀ, 0],
[I, 0], [0, I_nf]].  The kernel sums H_j = Σ_p w J Jᵀ, g_j = Σ_p w J r and the cost
in float64 in a fixed order, H = T H_j Tᵀ is formed in float64, and the Schur
Grams Γ_kl = Σ_p e_k C⁻¹ e_lᵀ are accumulated in float64
(``LinearSystem.gram_dtype``).  S = B − Σ T_k Γ_kl T_lᵀ cancels most of B in a
poorly conditioned window, so float32 sums there (the former block form, summed
with float32 atomics) moved the step by about 4e-4 of its size.

Importing this module is cheap and safe without CUDA: the kernels are built
only at first use (:mod:`droidw_backend_cuda.build`).
"""

from __future__ import annotations

import os

import torch
from torch import Tensor

from droidw_cli.ba.params import BAParams
from droidw_cli.ba.schur import BlockLayout, LinearSystem
from droidw_cli.ba.types import BAState, EdgeSet
from droidw_cli.geometry.lie import adjoint_matrix
from droidw_cli.geometry.projection import FOCAL_DOF, POSE_DOF, relative_poses
from droidw_backend_cpu.backend import CpuBackend
from droidw_backend_cpu.linearize import expand_to_both_poses
from droidw_backend_cuda import build

#: codes of the kernels' enums (csrc/droidw_ba.h)
# "relative" uses the clamp mapping on u already rescaled by weighting_input (shared Python code)
UNCERTAINTY_CODES = {"off": 0, "clamp": 1, "inverse": 2, "relative": 1}
FOCAL_CODES = {"none": 0, "shared": 1, "xy": 2}


def _relative(poses: Tensor, ii: Tensor, jj: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(rel (E, 12) = [R row-major, t], R, t) of G_ij = G_j G_i⁻¹."""
    rot, trans = relative_poses(poses, ii, jj)
    return torch.cat((rot.reshape(-1, 9), trans), dim=1).contiguous(), rot, trans


class CudaBackend(CpuBackend):
    """Uncertainty-aware dense BA with CUDA kernels (same maths as the CPU backend)."""

    name = "cuda"
    feature_layout = "stored"  # float16 on the GPU; the kernels take channels-first features

    def __init__(self, device: str | torch.device = "cuda") -> None:
        super().__init__()
        self._device = torch.device(device)
        # Same input, same output, as on the CPU: the shared solve's index_add_ sums with atomics on CUDA
        # unless torch is asked for its deterministic kernels (cuBLAS then needs a fixed workspace).
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
        torch.use_deterministic_algorithms(True, warn_only=True)

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        """Never builds: reports a missing device, a past build failure, or readiness."""
        if not torch.cuda.is_available():
            return False, "no CUDA device"
        err = build.build_error()
        if err is not None:
            return False, f"build failed: {err}"
        from torch.utils import cpp_extension

        if cpp_extension.CUDA_HOME is None:
            return False, "no CUDA toolkit (nvcc) to build the kernels; set CUDA_HOME"
        state = "kernels loaded" if build.is_built() else f"kernels built at first use into {build.build_directory()}"
        return True, f"{torch.cuda.get_device_name(0)}; {state}"

    @classmethod
    def ensure_built(cls, verbose: bool = False) -> None:
        """Build (or load the cached) kernels now; raises ``build.KernelBuildError``."""
        build.load_kernels(verbose=verbose)

    @property
    def device(self) -> torch.device:
        return self._device

    def _linearize(self, state: BAState, edges: EdgeSet, u_map: Tensor | None, params: BAParams,
                   layout: BlockLayout) -> LinearSystem:
        k = build.load_kernels()
        rel, rot, trans = _relative(state.poses, edges.ii, edges.jj)
        n, h, w = state.disps.shape
        e = edges.num_edges
        cfg = k.LinearizeConfig()
        cfg.fx, cfg.fy, cfg.cx, cfg.cy = (float(v) for v in state.intrinsics.tolist())
        cfg.min_depth = params.min_depth
        cfg.flow_weight_scale = params.flow_weight_scale
        cfg.uncertainty_mode = UNCERTAINTY_CODES[params.uncertainty.mode] if u_map is not None else 0
        cfg.bidirectional = bool(params.uncertainty.bidirectional)
        cfg.focal_mode = FOCAL_CODES[params.optimize_focal]
        cfg.with_depth = not params.motion_only
        inputs = k.LinearizeInputs()
        inputs.rel = rel
        inputs.disps = state.disps.contiguous()
        inputs.ii, inputs.jj = edges.ii.contiguous(), edges.jj.contiguous()
        inputs.target = edges.target.reshape(e, h * w, 2).contiguous()
        inputs.weight = edges.weight.reshape(e, h * w, 2).contiguous()
        if u_map is not None:
            inputs.umap = u_map.contiguous()
        hess_j, grad_j, erows, cdiag, wvec, cost = k.linearize(cfg, inputs)  # sums in float64
        # T_k holds float32 values (from the float32 poses); in float64 only so that H = T H_j Tᵀ stays float64
        tmat, hess, grad = expand_to_both_poses(adjoint_matrix(rot, trans).double(), hess_j, grad_j)
        if params.motion_only:
            return LinearSystem(hess, grad, None, None, None, cost.reshape(()))
        assert erows.shape[1] == POSE_DOF + FOCAL_DOF[params.optimize_focal]
        return LinearSystem(hess, grad, None, cdiag, wvec, cost.reshape(()), erows=erows, tmat=tmat.float(),
                            gram_dtype=torch.float64)

    def _similarity_term(self, state: BAState, ii: Tensor, jj: Tensor, target: Tensor, omega: Tensor, u: Tensor,
                         params: BAParams) -> tuple[Tensor, Tensor]:
        k = build.load_kernels()
        unc = params.uncertainty
        cfg = k.SimilarityConfig()
        cfg.fx, cfg.fy, cfg.cx, cfg.cy = (float(v) for v in state.intrinsics.tolist())
        cfg.min_depth = params.min_depth
        cfg.gamma_data = unc.gamma_data
        cfg.sim_threshold = unc.sim_threshold
        cfg.geo_sigma = unc.geo_sigma
        inputs = k.SimilarityInputs()
        inputs.rel = _relative(state.poses, ii, jj)[0]
        inputs.disps = state.disps.contiguous()
        inputs.ii, inputs.jj = ii.contiguous(), jj.contiguous()
        inputs.omega = omega.float().contiguous()
        inputs.features = state.features.float().contiguous()
        inputs.u = u.contiguous()
        if unc.geo_sigma > 0:
            inputs.target = target.float().reshape(target.shape[0], -1, 2).contiguous()
        grad, loss = k.similarity(cfg, inputs)
        return grad, loss.reshape(())
