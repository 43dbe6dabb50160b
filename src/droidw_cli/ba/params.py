"""Parameters of the uncertainty-aware bundle adjustment (DROID-W Eq. 4-9).

All defaults are the official DROID-W values listed in ``droid-w.md``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

UNCERTAINTY_MODES = ("clamp", "inverse", "relative")
FOCAL_MODES = ("none", "shared", "xy")


@dataclass(frozen=True)
class UncertaintyParams:
    """The dynamic-uncertainty model u = softplus(θ·F + b) and its optimiser.

    Attributes:
        enable: weight BA residuals by the uncertainty and optimise θ.  Off gives
            the plain DROID-style baseline.
        mode: how u becomes a residual weight.
            ``"clamp"`` (official code): w ← w · clamp(1 / max(45u − 35, 0.1), 0, 1),
            so u ≤ 0.8 leaves w untouched and larger u shrinks it fast.
            ``"inverse"`` (paper Eq. 5): w ← w / u.
            ``"relative"`` (droidw): the clamp mapping applied to u rescaled so that
            the window's median pixel sits at 0.75, just under the knee; see
            :func:`droidw_cli.ba.uncertainty.weighting_input`.
        bidirectional: also weight by u_j sampled at p_ij.
        gamma_data: γ_data, weight of E_sim (Eq. 7).
        gamma_prior: γ_prior, weight of E_prior = Σ log(u + 1) (Eq. 8).  0 is the
            "no prior" ablation.
        lr: λ, gradient-descent step on θ (Eq. 9).
        weight_decay: η in θ ← θ − λ·g − η·θ (Eq. 9).
        sim_threshold: s = cos(F_i, F_ij) below this is set to 0 (official: 0.5).
        min_frame_gap: E_sim uses only edges with |i − j| ≥ this (official: 2).
        softplus_offset: u = log(offset + exp(θ·F + b)); official 1.1 so u > 0.095.
        warmup_iters: BA iterations after initialisation run unweighted (official 8).
        freeze_in_global: θ stays fixed during the final global BA.
        average_per_keyframe: average the data term per keyframe by its number of
            E_sim edges (see :mod:`droidw_cli.ba.uncertainty`); False gives the plain
            mean over edges.
        geo_sigma: droidw extension, 0 = off (pure DROID-W).  s is multiplied by
            exp(−(r/geo_sigma)²), r = ‖p*_ij − p_ij‖ in grid pixels, so a pixel is
            "consistent" only if it also lands where its correspondence says.
        evidence: droidw extension (used by the tracker): append per-pixel evidence
            channels (multi-view flow residual, correspondence confidence) to the
            affine map's inputs, u = softplus(θ·[F; X] + b).
    """

    enable: bool = True
    mode: str = "clamp"
    bidirectional: bool = False
    gamma_data: float = 0.1
    gamma_prior: float = 0.05
    lr: float = 0.1
    weight_decay: float = 0.002
    sim_threshold: float = 0.5
    min_frame_gap: int = 2
    softplus_offset: float = 1.1
    warmup_iters: int = 8
    freeze_in_global: bool = True
    average_per_keyframe: bool = True
    geo_sigma: float = 0.0
    evidence: bool = False

    def __post_init__(self) -> None:
        if self.mode not in UNCERTAINTY_MODES:
            raise ValueError(f"uncertainty.mode must be one of {UNCERTAINTY_MODES}, got {self.mode!r}")
        if self.softplus_offset <= 0:
            raise ValueError("uncertainty.softplus_offset must be > 0")
        if self.min_frame_gap < 0 or self.lr < 0 or self.weight_decay < 0 or self.geo_sigma < 0:
            raise ValueError("uncertainty.min_frame_gap, lr and weight_decay must be >= 0")


@dataclass(frozen=True)
class BAParams:
    """One Gauss-Newton iteration's settings (DROID-W Eq. 4-5, official kernels).

    Attributes:
        flow_weight_scale: the confidence w_ij is scaled by this (official 0.001).
        gamma_depth: γ_d of the depth-prior term γ_d Σ ‖d_i − D_i‖² (0.001 indoor,
            0.01 outdoor).
        depth_damping: η added to the diagonal depth block C (no prior).
        prior_damping: α added to C where a depth prior exists.
        pose_damping_rel: diag(S) += pose_damping_rel · diag(S) ...
        pose_damping_abs: ... + pose_damping_abs  (official 1e-4 and 0.1).
        t0: poses with index < t0 are fixed (t0 = 1 removes the gauge freedom).
        motion_only: update poses only; disparities stay fixed.
        min_disp: disparities are clamped to at least this after each step.
        min_depth: points with depth below this get weight 0 (Eq. 1).
        optimize_focal: ``"none"``, ``"shared"`` (one f for fx and fy) or ``"xy"``.
        uncertainty: the uncertainty model and its optimiser.
    """

    flow_weight_scale: float = 0.001
    gamma_depth: float = 0.001
    depth_damping: float = 1e-7
    prior_damping: float = 1e-4
    pose_damping_rel: float = 1e-4
    pose_damping_abs: float = 0.1
    t0: int = 1
    motion_only: bool = False
    min_disp: float = 1e-3
    min_depth: float = 0.05
    optimize_focal: str = "none"
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)

    def __post_init__(self) -> None:
        if self.optimize_focal not in FOCAL_MODES:
            raise ValueError(f"ba.optimize_focal must be one of {FOCAL_MODES}, got {self.optimize_focal!r}")
        if self.t0 < 0:
            raise ValueError("ba.t0 must be >= 0")
        if self.min_disp <= 0 or self.min_depth < 0:
            raise ValueError("ba.min_disp must be > 0 and ba.min_depth >= 0")
        if min(self.depth_damping, self.prior_damping, self.pose_damping_rel, self.pose_damping_abs,
               self.gamma_depth, self.flow_weight_scale) < 0:
            raise ValueError("ba damping, gamma_depth and flow_weight_scale must be >= 0")
