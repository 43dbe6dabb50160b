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


class BackendUnavailable(RuntimeError):
    """The backend cannot run on this machine (the message says why)."""


class BABackend(ABC):
    """Operations on :class:`BAState` / :class:`EdgeSet` (DROID-W Eq. 1-9)."""

    #: registry name, e.g. ``"cpu"``
    name: str = ""

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
        """One damped Gauss-Newton iteration on poses (≥ t0) and disparities (Eq. 4-5)."""

    @abstractmethod
    def uncertainty_step(self, state: BAState, edges: EdgeSet, params: BAParams) -> UncertaintyStepResult:
        """One gradient step on θ of u = softplus(θ·F + b) (Eq. 6-9, supp. Eq. 11-13)."""


def validate_inputs(state: BAState, edges: EdgeSet, need_features: bool = False) -> None:
    """Refuse malformed BA input with a clear ``ValueError``.

    Checks: non-empty edges, matching shapes, indices in range, finite values.
    """
    n = state.num_frames
    if state.poses.ndim != 2 or state.poses.shape[1] != 7:
        raise ValueError(f"poses must have shape (N, 7), got {tuple(state.poses.shape)}")
    if state.disps.ndim != 3 or state.disps.shape[0] != n:
        raise ValueError(f"disps must have shape (N={n}, H, W), got {tuple(state.disps.shape)}")
    if state.intrinsics.shape != (4,):
        raise ValueError(f"intrinsics must have shape (4,), got {tuple(state.intrinsics.shape)}")
    h, w = state.grid
    e = edges.num_edges
    if e == 0:
        raise ValueError("the edge set is empty: BA needs at least one edge (i, j)")
    if edges.ii.shape != (e,) or edges.jj.shape != (e,):
        raise ValueError(f"ii and jj must both have shape (E,), got {tuple(edges.ii.shape)} and {tuple(edges.jj.shape)}")
    for name, t in (("target", edges.target), ("weight", edges.weight)):
        if t.shape != (e, h, w, 2):
            raise ValueError(f"{name} must have shape (E={e}, H={h}, W={w}, 2), got {tuple(t.shape)}")
    lo = int(torch.minimum(edges.ii.min(), edges.jj.min()))
    hi = int(torch.maximum(edges.ii.max(), edges.jj.max()))
    if lo < 0 or hi >= n:
        raise ValueError(f"edge index out of range: indices span [{lo}, {hi}] but there are {n} frames")
    if bool((edges.ii == edges.jj).any()):
        raise ValueError("an edge connects a frame to itself (ii == jj)")
    for name, t in (("target", edges.target), ("weight", edges.weight), ("poses", state.poses),
                    ("disps", state.disps), ("intrinsics", state.intrinsics)):
        if not bool(torch.isfinite(t).all()):
            raise ValueError(f"{name} contains NaN or Inf")
    if need_features:
        if state.features is None or state.theta is None:
            raise ValueError("uncertainty_step needs state.features and state.theta")
        if state.features.ndim != 4 or state.features.shape[0] != n or tuple(state.features.shape[2:]) != (h, w):
            raise ValueError(f"features must have shape (N={n}, C, H={h}, W={w}), got {tuple(state.features.shape)}")
        if state.theta.shape != (state.features.shape[1] + 1,):
            raise ValueError(f"theta must have shape (C+1={state.features.shape[1] + 1},), got {tuple(state.theta.shape)}")
    if state.depth_prior is not None and state.depth_prior.shape != state.disps.shape:
        raise ValueError(f"depth_prior must match disps {tuple(state.disps.shape)}, got {tuple(state.depth_prior.shape)}")
