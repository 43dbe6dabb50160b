"""Runs BA iterations on a window of the keyframe buffer through a backend.

Each iteration interleaves (DROID-W §3.3) one gradient step on the
uncertainty map θ (``uncertainty_step``) with one Gauss-Newton step on poses
and disparities (``ba_step``).  The first ``warmup_iters`` iterations after
initialisation run with the uncertainty weighting off, as in the official
code, and θ is left untouched when ``optimize_theta`` is False (global BA).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import torch
from torch import Tensor

from droidw_cli.ba.interface import BABackend
from droidw_cli.ba.params import BAParams
from droidw_cli.ba.types import BAState, EdgeSet
from droidw_cli.slam.evidence import evidence_maps
from droidw_cli.slam.keyframes import KeyframeBuffer


@dataclass
class SharedState:
    """State shared across windows: intrinsics on the 1/8 grid, θ, and the iteration counter."""

    intrinsics: Tensor
    theta: Tensor | None
    iterations: int = 0


def window_state(buffer: KeyframeBuffer, lo: int, hi: int, shared: SharedState, with_features: bool,
                 feature_layout: str = "stored") -> BAState:
    """A :class:`BAState` for keyframes [lo, hi) of the buffer.

    Poses, disparities and the prior are copies; the features are the buffer's
    float16 maps stacked (``feature_layout`` "stored"), which the backends only
    read, or converted to float32 channels-last ("float32_channels_last", see
    :attr:`BABackend.feature_layout`), the same values in the layout the CPU
    backend computes on, so that it keeps no second copy of them.
    """
    feats = None
    if with_features and buffer.features is not None:
        if feature_layout == "float32_channels_last":
            feats = buffer.feature_block(lo, hi, torch.float32, channels_last=True)
        elif feature_layout == "stored":
            feats = buffer.feature_block(lo, hi)
        else:
            raise ValueError(f"unknown feature layout {feature_layout!r}")
    return BAState(
        poses=buffer.poses[lo:hi].clone(),
        disps=buffer.disps[lo:hi].clone(),
        intrinsics=shared.intrinsics.clone(),
        features=feats,
        theta=shared.theta.clone() if (feats is not None and shared.theta is not None) else None,
        depth_prior=buffer.depth_prior[lo:hi].clone() if buffer.has_prior else None,
    )


def robust_edges(backend: BABackend, state: BAState, edges: EdgeSet, sigma: float, min_depth: float,
                 projection: tuple[Tensor, Tensor] | None = None) -> EdgeSet:
    """The edges with their confidences times the Cauchy IRLS weight of their current residual.

    With r = ‖p*_ij − p_ij‖ (grid px) under the state's poses and disparities,
    the Cauchy loss ρ(r) = σ²/2 · log(1 + r²/σ²) has the IRLS weight
    ρ'(r)/r = 1 / (1 + r²/σ²), so a Gauss-Newton step on Σ w·ρ(r) is one on
    Σ w / (1 + r²/σ²) · r² with the factor frozen at the linearisation point.
    Correspondences far from the rigid prediction (movers the masks missed,
    flow that failed) lose their pull instead of bending poses quadratically.
    ``projection``: the backend's ``reproject`` of these edges under this state, when the caller has it.
    """
    coords, valid = backend.reproject(state, edges.ii, edges.jj, min_depth) if projection is None else projection
    coords = coords.to(edges.target)
    dx = edges.target[..., 0] - coords[..., 0]  # per component: a sum over a last axis of 2 is slow on CPU
    dy = edges.target[..., 1] - coords[..., 1]
    r2 = dx * dx + dy * dy
    factor = torch.where(valid.to(r2.device), 1.0 / (1.0 + r2 / sigma ** 2), torch.ones_like(r2))
    return EdgeSet(edges.ii, edges.jj, edges.target, edges.weight * factor.unsqueeze(-1).to(edges.weight))


def run_window(backend: BABackend, buffer: KeyframeBuffer, lo: int, hi: int, edges: EdgeSet, params: BAParams,
               shared: SharedState, iters: int, fixed: int, optimize_theta: bool = True,
               robust_sigma: float = 0.0) -> float:
    """Optimise keyframes [lo, hi) for ``iters`` iterations; the first ``fixed`` stay put.

    ``robust_sigma`` > 0 (grid px): every Gauss-Newton step reweights the edges by
    the Cauchy loss of their current residuals (:func:`robust_edges`).
    Writes poses, disparities, intrinsics and θ back.  Returns the final cost.
    """
    unc = params.uncertainty
    use_unc = unc.enable and buffer.features is not None and shared.theta is not None
    state = window_state(buffer, lo, hi, shared, use_unc, getattr(backend, "feature_layout", "stored"))
    cost = float("nan")
    for _ in range(iters):
        weighted = use_unc and shared.iterations >= unc.warmup_iters
        evidence = use_unc and unc.evidence
        # one reprojection for both users: θ's step leaves poses, disparities and intrinsics as they are
        projection = backend.reproject(state, edges.ii, edges.jj, params.min_depth) \
            if evidence or robust_sigma > 0 else None
        if evidence:
            state = state.with_(map_inputs=evidence_maps(backend, state, edges, params.min_depth, projection))
        if weighted and optimize_theta:
            state = state.with_(theta=backend.uncertainty_step(state, edges, params).theta)
        step_params = dataclasses.replace(params, t0=fixed, uncertainty=dataclasses.replace(unc, enable=weighted))
        step_edges = robust_edges(backend, state, edges, robust_sigma, params.min_depth, projection) \
            if robust_sigma > 0 else edges
        result = backend.ba_step(state, step_edges, step_params)
        state, cost = result.state, result.cost
        shared.iterations += 1
    buffer.poses[lo:hi] = state.poses
    buffer.disps[lo:hi] = state.disps
    shared.intrinsics = state.intrinsics.clone()
    if state.theta is not None and optimize_theta:
        shared.theta = state.theta.clone()
    return cost
