"""Native CPU backend: the Gauss-Newton step, the uncertainty data term and the reprojection in C++.

:class:`NativeBackend` subclasses :class:`droidw_backend_cpu.CpuBackend` (input
checks, the uncertainty map u = softplus(θ·F + b) and the θ update are shared)
and replaces, with kernels built by :mod:`droidw_backend_native.build`,

* ``ba_step`` (Eq. 4-5): per depth frame, one fused pass over its out-edges'
  pixels forms the residuals, the weights w = w_ij·scale·f(u_i)[·f(u_j(p_ij))],
  the pose-j / focal Jacobian rows and their per-edge Hessian blocks, the E
  rows e_k, C and w (with the disparity prior), then the frame's Schur Grams
  Σ_p e_k C⁻¹ e_lᵀ; S = Σ T_k H_j Tᵀ − Σ T_k Γ_kl T_lᵀ is assembled in float64
  on the active nodes, Cholesky-solved, and Δd back-substituted
  (``csrc/linearize.cpp``, ``csrc/ba_step.cpp``).  The pose and focal updates
  T ← Exp(Δξ)·T are the shared Python ones (:mod:`droidw_cli.ba.schur`).
* ``_similarity_term`` (Eq. 7): γ_data·E_sim and ∂/∂u (``csrc/similarity.cpp``).
* ``reproject`` (Eq. 1) (``csrc/reproject.cpp``).

The per-pixel maths is the header shared with the CUDA kernels
(:mod:`droidw_cli.ba.csrc`).  Sums over pixels run per frame or per edge on one
thread, in float32 over tiles of 64 pixels and float64 beyond, and are combined
in a fixed order: the same input gives the same output whatever the number of
threads (torch's, ``torch.set_num_threads``).
"""

from __future__ import annotations

from types import SimpleNamespace

import torch
from torch import Tensor

from droidw_cli.ba.params import BAParams
from droidw_cli.ba.schur import active_nodes, apply_focal_update
from droidw_cli.ba.types import BAState, BAStepResult, EdgeSet
from droidw_cli.geometry.lie import normalize_pose, pose_compose, se3_exp
from droidw_cli.geometry.projection import FOCAL_DOF, relative_poses
from droidw_backend_cpu.backend import CpuBackend
from droidw_backend_native import build

#: codes of the kernels' enums (droidw_cli/ba/csrc/droidw_pixel.h)
# "relative" uses the clamp mapping on u already rescaled by weighting_input (shared Python code)
UNCERTAINTY_CODES = {"off": 0, "clamp": 1, "inverse": 2, "relative": 1}
FOCAL_CODES = {"none": 0, "shared": 1, "xy": 2}


def relative_rows(poses: Tensor, ii: Tensor, jj: Tensor) -> Tensor:
    """(E, 12) float32 rows [R row-major, t] of G_ij = G_j G_i⁻¹."""
    rot, trans = relative_poses(poses, ii, jj)
    return torch.cat((rot.reshape(-1, 9), trans), dim=1).float().contiguous()


def _pinhole(cfg, intrinsics: Tensor) -> None:
    cfg.fx, cfg.fy, cfg.cx, cfg.cy = (float(v) for v in intrinsics.tolist())


class NativeBackend(CpuBackend):
    """Uncertainty-aware dense BA with fused C++ kernels (same maths as the CPU backend)."""

    name = "native"
    #: where no compiler can build the kernels, the registry runs this backend instead (and says so)
    fallback = "cpu"

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        """Never builds: reports a past build failure, a missing compiler, or readiness."""
        threads = f"{torch.get_num_threads()} CPU threads"
        if build.is_built() or build.cached_library() is not None:
            return True, f"C++ kernels built ({build.build_directory()}), {threads}"
        err = build.build_error()
        if err is not None:
            return False, f"build failed: {err}"
        missing = build.missing_tool()
        if missing is not None:
            return False, missing
        return True, f"C++ kernels built at first use into {build.build_directory()}, {threads}"

    @classmethod
    def ensure_built(cls, verbose: bool = False) -> None:
        """Build (or load the cached) kernels now; raises ``build.KernelBuildError``."""
        build.load_kernels(verbose=verbose)

    # --------------------------------------------------------------- interface
    def reproject(self, state: BAState, ii: Tensor, jj: Tensor, min_depth: float = 0.05) -> tuple[Tensor, Tensor]:
        st, ii, jj = self._reproject_inputs(state, ii, jj)
        k = build.load_kernels()
        return tuple(k.reproject(relative_rows(st.poses, ii, jj), st.disps.contiguous(), st.intrinsics,
                                 ii.contiguous(), float(min_depth)))

    def ba_step(self, state: BAState, edges: EdgeSet, params: BAParams) -> BAStepResult:
        self._validate(state, edges)
        st, ed = self._prepare(state, edges)
        k = build.load_kernels()
        nf = FOCAL_DOF[params.optimize_focal]
        # the kernel groups edges by frame itself; of the block layout only the node counts are needed here
        layout = SimpleNamespace(num_frames=st.num_frames, num_nodes=st.num_frames + (1 if nf else 0), nf=nf)
        slot, ids = active_nodes(layout, ed.ii, ed.jj, params.t0)
        n, h, w = st.disps.shape
        u_map = self.uncertainty_weights(st, params)
        cfg = k.StepConfig()
        _pinhole(cfg, st.intrinsics)
        cfg.min_depth, cfg.flow_weight_scale = params.min_depth, params.flow_weight_scale
        cfg.uncertainty_mode = UNCERTAINTY_CODES[params.uncertainty.mode] if u_map is not None else 0
        cfg.bidirectional = bool(params.uncertainty.bidirectional)
        cfg.focal_mode = FOCAL_CODES[params.optimize_focal]
        cfg.motion_only = bool(params.motion_only)
        cfg.gamma_depth, cfg.depth_damping, cfg.prior_damping = (params.gamma_depth, params.depth_damping,
                                                                 params.prior_damping)
        cfg.pose_damping_rel, cfg.pose_damping_abs = params.pose_damping_rel, params.pose_damping_abs
        cfg.min_disp = params.min_disp
        inputs = k.StepInputs()
        inputs.rel = relative_rows(st.poses, ed.ii, ed.jj)
        inputs.disps = st.disps.contiguous()
        inputs.ii, inputs.jj = ed.ii.contiguous(), ed.jj.contiguous()
        inputs.target, inputs.weight = ed.target, ed.weight  # (E, H, W, 2), read through their strides
        inputs.slot = slot.contiguous()
        if u_map is not None:
            inputs.umap = u_map.float().contiguous()
        if st.depth_prior is not None:
            inputs.prior = st.depth_prior.reshape(n, h * w).contiguous()
        node_dx, disps, cost, solved = k.ba_step(cfg, inputs)
        cost = float(cost)
        if not bool(solved):
            return BAStepResult(st, cost, False)
        pose_ids = ids[ids < layout.num_frames]
        poses = st.poses.clone()
        if pose_ids.numel():
            dx = node_dx.index_select(0, pose_ids).to(poses.dtype)
            poses[pose_ids] = normalize_pose(pose_compose(se3_exp(dx), poses[pose_ids]))
        intr = st.intrinsics
        if layout.nf:
            intr = apply_focal_update(intr, node_dx[layout.num_frames].to(intr.dtype), params.optimize_focal)
        return BAStepResult(st.with_(poses=poses, disps=disps, intrinsics=intr), cost, True)

    def _similarity_term(self, state: BAState, ii: Tensor, jj: Tensor, target: Tensor, omega: Tensor, u: Tensor,
                         params: BAParams) -> tuple[Tensor, Tensor]:
        k = build.load_kernels()
        unc = params.uncertainty
        cl, norms = self._features.get(state.features)  # float32 channels-last, cached while unchanged
        cfg = k.SimilarityConfig()
        _pinhole(cfg, state.intrinsics)
        cfg.min_depth = params.min_depth
        cfg.gamma_data, cfg.sim_threshold, cfg.geo_sigma = unc.gamma_data, unc.sim_threshold, unc.geo_sigma
        inputs = k.SimilarityInputs()
        inputs.rel = relative_rows(state.poses, ii, jj)
        inputs.disps = state.disps.contiguous()
        inputs.ii, inputs.jj = ii.contiguous(), jj.contiguous()
        inputs.omega = omega.float().contiguous()
        inputs.features = cl.permute(0, 2, 3, 1).contiguous()  # a view of the channels-last table, no copy
        inputs.norms = norms.contiguous()
        inputs.u = u.float().contiguous()
        if unc.geo_sigma > 0:
            inputs.target = target.float().reshape(target.shape[0], -1, 2).contiguous()
        grad, loss = k.similarity(cfg, inputs)
        return grad, loss.float().reshape(())
