"""The one uncertainty-BA interface every backend implements.

A backend is a class registered under the ``droidw.backends`` entry-point
group.  The CPU backend (``backends/cpu``) is the reference; others must agree
with it to tolerance.  Input checking lives here so that every backend refuses
bad input with the same clear messages.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import torch
from torch import Tensor

from droidw_cli.ba.params import BAParams
from droidw_cli.ba.types import BAState, BAStepResult, EdgeSet, UncertaintyStepResult


class BABackend(ABC):
    """Operations on :class:`BAState` / :class:`EdgeSet` (DROID-W Eq. 1-9)."""

    #: registry name, e.g. ``"cpu"``
    name: str = ""
    #: the features the tracker puts in a window's :class:`BAState`: ``"stored"`` (the keyframe
    #: buffer's dtype, channels-first) or ``"float32_channels_last"`` (what the CPU backend computes
    #: on; converted from the buffer directly, the window needs no stacked float16 copy beside it)
    feature_layout: str = "stored"
    #: the backend that runs instead where this one cannot (e.g. no compiler for its kernels), or None: asking
    #: for it by name then fails with a clear error (see :func:`droidw_cli.ba.registry.resolve_backend`)
    fallback: str | None = None

    @classmethod
    @abstractmethod
    def availability(cls) -> tuple[bool, str]:
        """(usable here, reason) — the reason is shown by ``droidw backends``."""

    @property
    @abstractmethod
    def device(self) -> torch.device:
        """The torch device the backend computes on."""

    @abstractmethod
    def reproject(self, state: BAState, ii: Tensor, jj: Tensor, min_depth: float = 0.05) -> tuple[Tensor, Tensor]:
        """Rigid correspondences p_ij = Π(G_j G_i⁻¹ ∘ Π⁻¹(p_i, d_i)) (Eq. 1).

        Returns (coords (E, H, W, 2) float32 grid (x, y) in frame jj,
        valid (E, H, W) bool: depth ≥ min_depth in both frames).
        """

    @abstractmethod
    def ba_step(self, state: BAState, edges: EdgeSet, params: BAParams) -> BAStepResult:
        """One damped Gauss-Newton iteration on poses (≥ t0) and disparities (Eq. 4-5).

        Residual r = p*_ij − p_ij, weight w_ij · flow_weight_scale · f(u_i)
        [· f(u_j(p_ij)) if bidirectional] where u comes from state.features and
        θ when ``params.uncertainty.enable`` (else unweighted), plus γ_d(d − D)²
        where D > 0.  Block-sparse Schur complement, float64 Cholesky of the
        reduced pose (+ log-focal) system; T ← Exp(Δξ)·T with Δξ = [v, ω];
        Δd = C⁻¹(w − EᵀΔξ); d ≥ min_disp.  ``cost`` is the energy before the
        step; ``solved`` False means the factorisation failed and the state is
        unchanged.  See :mod:`droidw_cli.ba.schur`.
        """

    @abstractmethod
    def uncertainty_step(self, state: BAState, edges: EdgeSet, params: BAParams) -> UncertaintyStepResult:
        """One gradient step on θ of u = softplus(θ·F + b) (Eq. 6-9, supp. Eq. 11-13).

        θ ← θ − λ g − η θ with g the analytic gradient of E_uncer as defined in
        :mod:`droidw_cli.ba.uncertainty` (per-keyframe edge averaging, E_sim only
        on edges with |frame_id_i − frame_id_j| ≥ min_frame_gap).  No E_sim
        edge: θ is returned unchanged with loss 0.
        """

    def release(self) -> None:
        """Drop whatever the backend keeps between calls to reuse work (caches of the last window).

        The tracker calls it after its last BA, so that the end of a run (masks,
        uncertainty maps, the result) does not hold on to a window's worth of
        cached features.  It must never change a later result; the default keeps nothing.
        """


def _all_finite(t: Tensor) -> bool:
    """True when every element is finite (a one-pass sum first; the exact test only if it fails)."""
    if t.numel() == 0:
        return True
    if bool(torch.isfinite(t.sum(dtype=torch.float64))):
        return True
    return bool(torch.isfinite(t).all())


def validate_inputs(state: BAState, edges: EdgeSet, need_features: bool = False,
                    check_edge_values: bool = True) -> None:
    """Refuse malformed BA input with a clear ``ValueError``.

    Checks: non-empty edges, integer indices in range and no self-edges,
    matching shapes (grid at least 2 × 2), finite values, non-negative weights,
    and, when ``need_features`` (or when features are given), the features, θ and
    frame ids.  ``check_edge_values=False`` skips the value checks of the edges'
    target and weight (finite, weight ≥ 0; full passes over E·HW·2 values) for a
    caller that has checked these very tensors already.
    """
    n = state.num_frames
    if state.poses.ndim != 2 or state.poses.shape[1] != 7:
        raise ValueError(f"poses must have shape (N, 7), got {tuple(state.poses.shape)}")
    if state.disps.ndim != 3 or state.disps.shape[0] != n:
        raise ValueError(f"disps must have shape (N={n}, H, W), got {tuple(state.disps.shape)}")
    if state.intrinsics.shape != (4,):
        raise ValueError(f"intrinsics must have shape (4,), got {tuple(state.intrinsics.shape)}")
    h, w = state.grid
    if h < 2 or w < 2:
        raise ValueError(f"the BA grid must be at least 2 x 2, got {h} x {w}")
    e = edges.num_edges
    if edges.ii.ndim != 1:
        raise ValueError(f"ii must have shape (E,), got {tuple(edges.ii.shape)}")
    if e == 0:
        raise ValueError("the edge set is empty: BA needs at least one edge (i, j)")
    if edges.ii.shape != (e,) or edges.jj.shape != (e,):
        raise ValueError(f"ii and jj must both have shape (E,), got {tuple(edges.ii.shape)} and {tuple(edges.jj.shape)}")
    if edges.ii.is_floating_point() or edges.jj.is_floating_point() or edges.ii.dtype == torch.bool:
        raise ValueError(f"ii and jj must be integer tensors, got {edges.ii.dtype} and {edges.jj.dtype}")
    for name, t in (("target", edges.target), ("weight", edges.weight)):
        if t.shape != (e, h, w, 2):
            raise ValueError(f"{name} must have shape (E={e}, H={h}, W={w}, 2), got {tuple(t.shape)}")
    lo = int(torch.minimum(edges.ii.min(), edges.jj.min()))
    hi = int(torch.maximum(edges.ii.max(), edges.jj.max()))
    if lo < 0 or hi >= n:
        raise ValueError(f"edge index out of range: indices span [{lo}, {hi}] but there are {n} frames")
    if bool((edges.ii == edges.jj).any()):
        raise ValueError("an edge connects a frame to itself (ii == jj)")
    values = (("target", edges.target), ("weight", edges.weight)) if check_edge_values else ()
    for name, t in values + (("poses", state.poses), ("disps", state.disps), ("intrinsics", state.intrinsics)):
        if not _all_finite(t):
            raise ValueError(f"{name} contains NaN or Inf")
    if check_edge_values and float(edges.weight.amin()) < 0:
        raise ValueError("weight must be >= 0")
    if not bool((state.intrinsics[:2] > 0).all()):
        raise ValueError(f"focal lengths must be positive, got {state.intrinsics[:2].tolist()}")
    if need_features and (state.features is None or state.theta is None):
        raise ValueError("uncertainty needs state.features and state.theta")
    if state.features is not None and state.theta is not None:
        if state.features.ndim != 4 or state.features.shape[0] != n or tuple(state.features.shape[2:]) != (h, w):
            raise ValueError(f"features must have shape (N={n}, C, H={h}, W={w}), got {tuple(state.features.shape)}")
        m = 0
        if state.map_inputs is not None:
            if state.map_inputs.ndim != 4 or state.map_inputs.shape[0] != n or tuple(state.map_inputs.shape[2:]) != (h, w):
                raise ValueError(f"map_inputs must have shape (N={n}, M, H={h}, W={w}), "
                                 f"got {tuple(state.map_inputs.shape)}")
            m = int(state.map_inputs.shape[1])
        width = state.features.shape[1] + m + 1
        if state.theta.shape != (width,):
            raise ValueError(f"theta must have shape (C+M+1={width},), got {tuple(state.theta.shape)}")
        if not _all_finite(state.theta):
            raise ValueError("theta contains NaN or Inf")
    if state.frame_ids is not None and state.frame_ids.shape != (n,):
        raise ValueError(f"frame_ids must have shape (N={n},), got {tuple(state.frame_ids.shape)}")
    if state.depth_prior is not None:
        if state.depth_prior.shape != state.disps.shape:
            raise ValueError(f"depth_prior must match disps {tuple(state.disps.shape)}, got {tuple(state.depth_prior.shape)}")
        if not _all_finite(state.depth_prior):
            raise ValueError("depth_prior contains NaN or Inf")
