"""Inconsistency maps between an observed keyframe and its predictions (ADD-SLAM §dynamic detection).

For each source view v (one prediction Î_v, D̂_v with validity V_v):

    I_err = ‖I − Î_v‖₂            (RGB Euclidean norm, colours in [0, 1])
    D_err = |D − D̂_v|             (depth in metres, D = 1/disp)
    τ_I = max(tau_scale · median_{V_v} I_err, color_floor)
    τ_D = max(tau_scale · median_{V_v} D_err, depth_floor)
    M_ic  = V_v ∩ ((I_err > τ_I) ∪ (D_err > τ_D))
    M_ic^d = M_ic ∩ (D − D̂_v < −m),   m = max(sign_margin · D, median_{V_v} D_err)

The sign rule separates the mover from the background it uncovered: a
moving object newly occluding the scene is *closer* than the prediction
(D < D̂), freshly exposed background is *farther* (D > D̂).  ADD-SLAM uses
m = 0; droidw asks for the observation to be closer by more than the typical
depth error and by ``sign_margin`` (5 %) of its depth, because pixels flagged
by colour alone (blended colours next to an occlusion edge, texture aliasing
on the 1/8 grid) have D − D̂ ≈ 0 and their sign is noise.  The errors are
long-tailed, so τ between 10× and 30× the median behaves alike — as long as
the movers cover clearly less than half of the valid pixels; beyond that the
median itself is inflated and recall drops.

τ is computed per source view (each prediction has its own error level).

Combination over views (documented rule): with n_valid the number of views
in which a pixel has a valid prediction and n_flag the number in which it is
in M_ic^d, the pixel is a dynamic seed when

    n_flag ≥ 1  and  n_flag ≥ min_fraction · n_valid      (default: at least half).

"At least half" rather than a strict majority, because where a mover
overlaps its own earlier position in one neighbour (D ≈ D̂ there) it is
usually caught by the neighbour on the other side only.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import Tensor

from droidw_cli.dynamics.params import DetectionParams


@dataclass(frozen=True)
class InconsistencyMaps:
    """Per-view error maps (S, h, w) and the combined dynamic seed mask (h, w).

    Attributes:
        color_err: I_err (0 where invalid).
        depth_err: D_err (0 where invalid).
        signed_depth: D − D̂ (0 where invalid).
        m_ic: M_ic per view (bool).
        m_dyn: combined seed mask M_ic^d (h, w) bool, see the module docstring.
        m_dyn_views: M_ic^d per view (bool).
        valid: prediction validity per view (bool).
        tau_color, tau_depth: (S,) thresholds used per view (inf for a view with no valid pixel).
    """

    color_err: Tensor
    depth_err: Tensor
    signed_depth: Tensor
    m_ic: Tensor
    m_dyn: Tensor
    m_dyn_views: Tensor
    valid: Tensor
    tau_color: Tensor
    tau_depth: Tensor


def _medians(err: Tensor, valid: Tensor) -> Tensor:
    """Median of ``err`` over the valid pixels of each view (S,); nan for a view with none."""
    flat = torch.where(valid, err, torch.full_like(err, float("nan"))).reshape(err.shape[0], -1)
    if flat.shape[1] == 0:
        return flat.new_full((flat.shape[0],), float("nan"))
    return torch.nanmedian(flat, dim=1).values


def _thresholds(med: Tensor, scale: float, floor: float) -> Tensor:
    """max(scale · median, floor) per view; inf for views with no valid pixel."""
    tau = torch.clamp(scale * med, min=floor)
    return torch.where(torch.isnan(med), torch.full_like(tau, float("inf")), tau)


def inconsistency(image: Tensor, disp: Tensor, pred_rgb: Tensor, pred_disp: Tensor, valid: Tensor,
                  tau_scale: float = 20.0, params: DetectionParams | None = None) -> InconsistencyMaps:
    """Inconsistency maps of the observation (image (h, w, 3), disp (h, w)) against S predictions.

    ``pred_rgb`` (S, h, w, 3), ``pred_disp`` (S, h, w) and ``valid`` (S, h, w) are the
    outputs of :func:`droidw_cli.dynamics.warp.predict_views`.
    """
    params = params or DetectionParams()
    if not tau_scale > 0:
        raise ValueError(f"tau_scale must be positive, got {tau_scale}")
    h, w = disp.shape[-2:]
    if image.shape != (h, w, 3) or disp.dim() != 2:
        raise ValueError(f"need image (h, w, 3) and disp (h, w), got {tuple(image.shape)} and {tuple(disp.shape)}")
    s = pred_disp.shape[0]
    if pred_rgb.shape != (s, h, w, 3) or pred_disp.shape != (s, h, w) or valid.shape != (s, h, w):
        raise ValueError("pred_rgb (S, h, w, 3), pred_disp (S, h, w) and valid (S, h, w) must match the observation")
    dtype = disp.dtype
    valid = valid & (disp > 0).unsqueeze(0) & (pred_disp > 0)
    one = torch.ones((), dtype=dtype, device=disp.device)
    depth = 1.0 / torch.where(disp > 0, disp, one)
    depth_hat = 1.0 / torch.where(valid, pred_disp, one)
    zero = torch.zeros((), dtype=dtype, device=disp.device)
    color_err = torch.where(valid, (image.to(dtype).unsqueeze(0) - pred_rgb.to(dtype)).norm(dim=-1), zero)
    signed = torch.where(valid, depth.unsqueeze(0) - depth_hat, zero)
    depth_err = signed.abs()

    med_d = _medians(depth_err, valid)
    tau_c = _thresholds(_medians(color_err, valid), tau_scale, params.color_floor)
    tau_d = _thresholds(med_d, tau_scale, params.depth_floor)
    m_ic = valid & ((color_err > tau_c.view(s, 1, 1)) | (depth_err > tau_d.view(s, 1, 1)))
    margin = torch.maximum(params.sign_margin * depth.unsqueeze(0), torch.nan_to_num(med_d, nan=0.0).view(s, 1, 1))
    m_dyn_views = m_ic & (signed < -margin)
    n_valid = valid.sum(0)
    n_flag = m_dyn_views.sum(0)
    m_dyn = (n_flag >= 1) & (n_flag.to(dtype) >= params.min_fraction * n_valid.to(dtype))
    return InconsistencyMaps(color_err, depth_err, signed, m_ic, m_dyn, m_dyn_views, valid, tau_c, tau_d)
