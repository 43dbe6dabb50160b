"""The reference backend: vectorised torch on the CPU (DROID-W Eq. 1-9).

Every operation is a tensor operation over edges and pixels (edges go in
memory-bounded chunks); the only Python loops run over chunks and over the
handful of distinct "blocks per frame" counts of the Schur complement.
Torch's intra-op thread pool is used as configured (``torch.get_num_threads()``,
by default one thread per core); the backend never changes it.

The three hooks ``_project``, ``_linearize`` and ``_similarity_term`` are the
hot paths; the CUDA backend subclasses this class and replaces them with
kernels, so the assembly, the Schur solve and the uncertainty update are shared.

**Work kept between calls** (a tracker iteration calls ``reproject`` for the
evidence maps, ``uncertainty_step`` and ``ba_step`` on one state): the last
reprojection (:class:`~droidw_backend_cpu.reproject.ProjectionCache`), the
features as float32 channels-last with θ[:C]·F for the last θ
(:class:`~droidw_backend_cpu.uncertainty.FeatureTable`), and which edge
tensors passed the value checks.  Each is keyed on the very tensor objects and
their version counters (bumped by every in-place write), so a reuse can never
see changed inputs; results are the same as from a fresh backend.
"""

from __future__ import annotations

import torch
from torch import Tensor

from droidw_cli.ba.interface import BABackend, validate_inputs
from droidw_cli.ba.params import BAParams
from droidw_cli.ba.schur import BlockLayout, LinearSystem, build_layout, solve_step
from droidw_cli.ba.types import BAState, BAStepResult, EdgeSet, UncertaintyStepResult
from droidw_cli.ba.uncertainty import (
    edge_objective_weights,
    finish_uncertainty_step,
    similarity_edge_mask,
    uncertainty_from_logits,
    weighting_input,
)
from droidw_backend_cpu.linearize import DEFAULT_CHUNK_BYTES, linearize
from droidw_backend_cpu.reproject import ProjectionCache, version
from droidw_backend_cpu.uncertainty import DEFAULT_FEATURE_CHUNK_BYTES, FeatureTable, similarity_data_term


class CpuBackend(BABackend):
    """Pure-torch uncertainty-aware dense BA (the reference implementation).

    Args:
        chunk_bytes: memory budget of the GN linearisation temporaries.
        feature_chunk_bytes: memory budget of the gathered features in the
            uncertainty step.
    """

    name = "cpu"
    feature_layout = "float32_channels_last"  # the FeatureTable uses such features as they are

    def __init__(self, chunk_bytes: int = DEFAULT_CHUNK_BYTES,
                 feature_chunk_bytes: int = DEFAULT_FEATURE_CHUNK_BYTES) -> None:
        self.chunk_bytes = int(chunk_bytes)
        self.feature_chunk_bytes = int(feature_chunk_bytes)
        self._features = FeatureTable()  # channel-last features of the last window, reused while unchanged
        self._projections = ProjectionCache()  # the last reprojection of an edge set, reused while unchanged
        self._checked_edges: tuple | None = None  # (target, weight) whose values passed validation, and versions

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        return True, f"torch {torch.__version__}, {torch.get_num_threads()} CPU threads"

    @property
    def device(self) -> torch.device:
        return torch.device("cpu")

    def release(self) -> None:
        """Forget the cached feature table, projection and edge check (rebuilt on the next call)."""
        self._features.clear()
        self._projections.clear()
        self._checked_edges = None

    # ----------------------------------------------------------------- helpers
    def _prepare(self, state: BAState, edges: EdgeSet | None = None) -> tuple[BAState, EdgeSet | None]:
        """The state (and edges) on this backend's device, float32, int64 indices."""
        dev = self.device
        f32 = {"device": dev, "dtype": torch.float32}
        st = BAState(
            poses=state.poses.to(**f32), disps=state.disps.to(**f32), intrinsics=state.intrinsics.to(**f32),
            features=None if state.features is None else state.features.to(dev),
            theta=None if state.theta is None else state.theta.to(**f32),
            depth_prior=None if state.depth_prior is None else state.depth_prior.to(**f32),
            frame_ids=None if state.frame_ids is None else state.frame_ids.to(device=dev, dtype=torch.long),
            map_inputs=None if state.map_inputs is None else state.map_inputs.to(**f32),
        )
        if edges is None:
            return st, None
        ed = EdgeSet(edges.ii.to(device=dev, dtype=torch.long), edges.jj.to(device=dev, dtype=torch.long),
                     edges.target.to(**f32), edges.weight.to(**f32))
        return st, ed

    def _validate(self, state: BAState, edges: EdgeSet, need_features: bool = False) -> None:
        """``validate_inputs``; the value checks of target and weight only once per (unchanged) edge set."""
        tensors = (edges.target, edges.weight)
        stamps = tuple(version(t) for t in tensors)
        known = self._checked_edges
        seen = (known is not None and None not in stamps and all(a is b for a, b in zip(known[0], tensors))
                and known[1] == stamps)
        validate_inputs(state, edges, need_features, check_edge_values=not seen)
        self._checked_edges = (tensors, stamps)

    # ------------------------------------------------------------------- hooks
    def _project(self, state: BAState, ii: Tensor, jj: Tensor, min_depth: float) -> tuple[Tensor, Tensor]:
        proj, _, _ = self._projections.get(state.poses, state.disps, state.intrinsics, ii, jj, min_depth)
        e = ii.shape[0]
        h, w = state.grid
        return proj.coords.permute(0, 2, 1).reshape(e, h, w, 2), proj.valid.reshape(e, h, w)

    def _linearize(self, state: BAState, edges: EdgeSet, u_map: Tensor | None, params: BAParams,
                   layout: BlockLayout) -> LinearSystem:
        return linearize(state.poses, state.disps, state.intrinsics, edges.ii, edges.jj, edges.target,
                         edges.weight, u_map, params, layout, self.chunk_bytes, projections=self._projections)

    def _similarity_term(self, state: BAState, ii: Tensor, jj: Tensor, target: Tensor, omega: Tensor, u: Tensor,
                         params: BAParams) -> tuple[Tensor, Tensor]:
        unc = params.uncertainty
        return similarity_data_term(state.poses, state.disps, state.intrinsics, ii, jj, omega, state.features, u,
                                    unc.gamma_data, unc.sim_threshold, params.min_depth, self.feature_chunk_bytes,
                                    target=target, geo_sigma=unc.geo_sigma, table=self._features,
                                    projections=self._projections)

    # --------------------------------------------------------------- interface
    def reproject(self, state: BAState, ii: Tensor, jj: Tensor, min_depth: float = 0.05) -> tuple[Tensor, Tensor]:
        st, ii, jj = self._reproject_inputs(state, ii, jj)
        return self._project(st, ii, jj, min_depth)

    def _reproject_inputs(self, state: BAState, ii: Tensor, jj: Tensor) -> tuple[BAState, Tensor, Tensor]:
        """The prepared state and the edge indices as long tensors on the device, checked: (E,) each, in range."""
        st, _ = self._prepare(state)
        ii = ii.to(device=self.device, dtype=torch.long)
        jj = jj.to(device=self.device, dtype=torch.long)
        if ii.ndim != 1 or ii.shape != jj.shape:
            raise ValueError(f"ii and jj must both have shape (E,), got {tuple(ii.shape)} and {tuple(jj.shape)}")
        if ii.numel() and (int(torch.minimum(ii.min(), jj.min())) < 0
                           or int(torch.maximum(ii.max(), jj.max())) >= st.num_frames):
            raise ValueError(f"edge index out of range for {st.num_frames} frames")
        return st, ii, jj

    def uncertainty_weights(self, state: BAState, params: BAParams) -> Tensor | None:
        """u (N, HW) used to weight the BA, or None when the BA runs unweighted."""
        unc = params.uncertainty
        if not unc.enable or state.features is None or state.theta is None:
            return None
        logits = self._features.logits(state.features, state.theta, state.map_inputs)
        u = uncertainty_from_logits(logits, unc.softplus_offset).reshape(state.num_frames, -1)
        return weighting_input(u, unc.mode)

    def ba_step(self, state: BAState, edges: EdgeSet, params: BAParams) -> BAStepResult:
        self._validate(state, edges)
        st, ed = self._prepare(state, edges)
        layout = build_layout(ed.ii, ed.jj, st.num_frames, params.optimize_focal)
        lin = self._linearize(st, ed, self.uncertainty_weights(st, params), params, layout)
        poses, disps, intr, cost, solved = solve_step(st.poses, st.disps, st.intrinsics, st.depth_prior,
                                                      ed.ii, ed.jj, lin, layout, params)
        return BAStepResult(st.with_(poses=poses, disps=disps, intrinsics=intr), cost, solved)

    def uncertainty_step(self, state: BAState, edges: EdgeSet, params: BAParams) -> UncertaintyStepResult:
        self._validate(state, edges, need_features=True)
        st, ed = self._prepare(state, edges)
        unc = params.uncertainty
        keep = similarity_edge_mask(ed.ii, ed.jj, st.keyframe_ids(), unc.min_frame_gap)
        if not bool(keep.any()):
            return UncertaintyStepResult(theta=st.theta.clone(), loss=0.0)
        if type(self)._similarity_term is CpuBackend._similarity_term:
            # project all edges once (kept for this state's GN step) and read the E_sim rows from it
            self._projections.get(st.poses, st.disps, st.intrinsics, ed.ii, ed.jj, params.min_depth)
        ii, jj = ed.ii[keep], ed.jj[keep]
        omega, involved = edge_objective_weights(ii, jj, st.num_frames, unc.average_per_keyframe)
        feats = self._features.get(st.features)[0]  # float32 channels-last, cached while the features are unchanged
        logits = self._features.logits(st.features, st.theta, st.map_inputs)
        u = uncertainty_from_logits(logits, unc.softplus_offset).reshape(st.num_frames, -1)
        data_grad, data_loss = self._similarity_term(st, ii, jj, ed.target[keep], omega, u, params)
        return finish_uncertainty_step(st.theta, feats, logits, data_grad, data_loss, involved, unc, st.map_inputs)
