"""The DROID-W dynamic-uncertainty model and its objective (Eq. 5-9, supp. Eq. 11-13).

Model (one affine map shared by every pixel, C + 1 parameters):

    a = θ[:C]·F + θ[C],      u = log(o + exp(a))      (o = softplus_offset, official 1.1)
    du/da = exp(a)/(o + exp(a)) = sigmoid(a − log o)

BA weight factor of a pixel with uncertainty u (``mode``):

    clamp   : clamp(1 / max(45 u − 35, 0.1), 0, 1)    (official code; u ≤ 0.8 → 1)
    inverse : 1 / u                                    (paper Eq. 5)

Objective, over the set K of E_sim edges (|id_i − id_j| ≥ min_frame_gap with
id = ``BAState.frame_ids``) and the set V of frames they touch:

    e_k     = Σ_p valid · (1 − s) / (u_i(p) · u_ij(p))
    s       = cos(F_i(p), F_ij(p)) clamped to [0, 1], and 0 where below sim_threshold
    P_n     = Σ_p log(1 + u_n(p))
    E_uncer = (1/|V|) Σ_{n∈V} [ γ_data · (1/|K_n|) Σ_{k∈K_n} e_k  +  γ_prior · P_n ]

where F_ij, u_ij are F_j, u_j bilinearly sampled at the current p_ij, ``valid`` is
"reprojection valid and inside the image", and K_n are the E_sim edges touching
frame n (as i or as j).  This is the official "gradients averaged per keyframe by
its number of edges": each keyframe contributes the mean over its edges.  It
is the same as weighting edge k by ω_k = (1/|K_i| + 1/|K_j|)/|V|.  With
``average_per_keyframe=False``, ω_k = 1/|K| (plain mean over edges).

Scale: the terms are sums over the pixels of a frame and means over frames
and edges, so the gradient does not grow with the window size, and the
official λ = 0.1 moves θ at a useful rate on the 1/8 grid (about 3000 pixels);
with per-pixel means it would need λ ≈ 300 (measured on the synthetic movers
problem: both learn the same map, λ·HW is what matters).

The gradient is analytic (features and p_ij are constants):

    ∂e/∂u_i = −t/u_i,   ∂e/∂u_ij = −t/u_ij,   t = ω_k γ_data valid (1 − s)/(u_i u_ij)
    ∂/∂u_j[corner c] = w_c ∂e/∂u_ij             (bilinear weights w_c)
    g = Σ_{n,p} G_n(p) · du/da · [F_n(p); 1],    G = Σ of the above + γ_prior/(|V| (1 + u))

and the update is θ ← θ − λ g − η θ.  Backends compute the data part of G
(``data_grad``, an (N, HW) map) and call :func:`finish_uncertainty_step`.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from droidw_cli.ba.params import UncertaintyParams
from droidw_cli.ba.types import UncertaintyStepResult

#: clamp-mode weight factor: clamp(1 / max(SLOPE·u − OFFSET, FLOOR), 0, 1)
CLAMP_SLOPE = 45.0
CLAMP_OFFSET = 35.0
CLAMP_FLOOR = 0.1
#: guards the cosine similarity against zero-norm features
COS_EPS = 1e-8


def map_input_matrix(features: Tensor, map_inputs: Tensor | None = None) -> Tensor:
    """The affine map's per-pixel inputs [F; X] as (N, C + M, HW) float32 (a copy when X is given)."""
    n, c, h, w = features.shape
    flat = features.reshape(n, c, h * w).float()
    if map_inputs is None:
        return flat
    return torch.cat((flat, map_inputs.reshape(n, -1, h * w).to(flat)), 1)


def _channels_last_rows(x: Tensor) -> Tensor | None:
    """x (N, C, H, W) as an (N·H·W, C) view when its memory is channels-last, else None."""
    n, c, h, w = x.shape
    if c > 1 and x.is_contiguous(memory_format=torch.channels_last) and not x.is_contiguous():
        return x.permute(0, 2, 3, 1).reshape(n * h * w, c)
    return None


def channel_dot(x: Tensor, vec: Tensor) -> Tensor:
    """Σ_c vec[c] x[n, c, p] → (N, HW) float32, for x (N, C, H, W) in either memory layout.

    One matrix-vector product over the pixels (no copy of x when it is float32).
    """
    n, c, h, w = x.shape
    vec = vec.to(device=x.device, dtype=torch.float32)
    rows = _channels_last_rows(x)
    if rows is not None:
        return torch.matmul(rows.float(), vec).reshape(n, h * w)
    return torch.matmul(vec, x.reshape(n, c, h * w).float())


def pixel_sum(x: Tensor, weights: Tensor) -> Tensor:
    """Σ_{n,p} weights[n, p] x[n, :, p] → (C,) float32, for x (N, C, H, W) in either memory layout.

    Channels-last: one vector-matrix product; channels-first: one matrix-vector
    product per frame (a batched matrix-vector ``bmm`` is several times slower on CPU).
    """
    n, c, h, w = x.shape
    weights = weights.reshape(n, h * w).float()
    rows = _channels_last_rows(x)
    if rows is not None:
        return torch.matmul(weights.reshape(-1), rows.float())
    flat = x.reshape(n, c, h * w)
    out = torch.zeros(c, dtype=torch.float32, device=x.device)
    for f in range(n):
        out.addmv_(flat[f].float(), weights[f])
    return out


def uncertainty_logits(features: Tensor, theta: Tensor, map_inputs: Tensor | None = None) -> Tensor:
    """a = θ[:-1]·[F; X] + θ[-1]: features (N, C, H, W) (+ map inputs (N, M, H, W)) → (N, H, W).

    The features may be channels-first or channels-last in memory.
    """
    n, c, h, w = features.shape
    theta = theta.to(device=features.device, dtype=torch.float32)
    a = channel_dot(features, theta[:c])
    if map_inputs is not None:
        a = a + channel_dot(map_inputs, theta[c:-1])
    return (a + theta[-1]).reshape(n, h, w)


def uncertainty_from_logits(logits: Tensor, offset: float) -> Tensor:
    """u = log(offset + exp(a)), computed stably."""
    return torch.logaddexp(logits, torch.full_like(logits, math.log(offset)))


def uncertainty_slope(logits: Tensor, offset: float) -> Tensor:
    """du/da = sigmoid(a − log offset)."""
    return torch.sigmoid(logits - math.log(offset))


def uncertainty_map(features: Tensor, theta: Tensor, offset: float = 1.1, map_inputs: Tensor | None = None) -> Tensor:
    """u (N, H, W) of every pixel (e.g. for a new keyframe, or for export)."""
    return uncertainty_from_logits(uncertainty_logits(features, theta, map_inputs), offset)


#: "relative" mode: the window's median u is mapped to this level before the clamp mapping
RELATIVE_LEVEL = 0.75


def weighting_input(u: Tensor, mode: str) -> Tensor:
    """The u the BA weighting sees: u itself, or for ``"relative"`` u · 0.75 / median(u).

    The clamp mapping only bites above u = 0.8, a level calibrated for DINOv2
    features.  With other features (XFeat here) the affine map settles at a
    different absolute level while still ranking movers above the background;
    rescaling by the window's median (the background, as long as movers cover
    less than half the view) puts the background just under the knee and the
    movers on the steep part, whatever the level.
    """
    if mode != "relative":
        return u
    return u * (RELATIVE_LEVEL / u.median().clamp_min(1e-6))


def weight_factor(u: Tensor, mode: str) -> Tensor:
    """The BA confidence multiplier of uncertainty u (see the module docstring)."""
    if mode in ("clamp", "relative"):  # "relative" gets u already rescaled by weighting_input
        return (1.0 / (CLAMP_SLOPE * u - CLAMP_OFFSET).clamp_min(CLAMP_FLOOR)).clamp(0.0, 1.0)
    if mode == "inverse":
        return 1.0 / u
    raise ValueError(f"unknown uncertainty mode {mode!r}")


def similarity_edge_mask(ii: Tensor, jj: Tensor, frame_ids: Tensor, min_gap: int) -> Tensor:
    """(E,) bool: the edges used by E_sim, |id[ii] − id[jj]| ≥ min_gap."""
    return (frame_ids[ii] - frame_ids[jj]).abs() >= min_gap


def edge_objective_weights(ii: Tensor, jj: Tensor, num_frames: int, per_keyframe: bool) -> tuple[Tensor, Tensor]:
    """(ω (K,) float32, involved (N,) bool) for the E_sim edges ii, jj (see module docstring)."""
    counts = torch.zeros(num_frames, device=ii.device, dtype=torch.float32)
    ones = torch.ones(ii.shape[0], device=ii.device, dtype=torch.float32)
    counts.index_add_(0, ii, ones).index_add_(0, jj, ones)
    involved = counts > 0
    if not per_keyframe:
        return ones / max(ii.shape[0], 1), involved
    nv = involved.sum().clamp_min(1).float()
    return (1.0 / counts[ii] + 1.0 / counts[jj]) / nv, involved


def similarity_score(cos: Tensor, threshold: float, residual: Tensor | None = None, geo_sigma: float = 0.0) -> Tensor:
    """s = clamp(cos, 0, 1) · exp(−(r/σ_g)²), set to 0 below ``threshold``.

    The geometric factor (droidw's extension, off when σ_g = 0) makes a pixel
    consistent only if it also lands where its correspondence target says:
    r = ‖p*_ij − p_ij‖ in grid pixels.
    """
    s = cos.clamp(0.0, 1.0)
    if residual is not None and geo_sigma > 0:
        s = s * torch.exp(-(residual / geo_sigma) ** 2)
    return torch.where(s < threshold, torch.zeros_like(s), s)


def theta_gradient(grad_u: Tensor, slope: Tensor, features: Tensor, map_inputs: Tensor | None = None) -> Tensor:
    """g = Σ G · du/da · [F; X; 1] for G, du/da (N, HW) → (C + M + 1,)."""
    ga = grad_u * slope
    parts = [pixel_sum(features, ga)]
    if map_inputs is not None:
        parts.append(pixel_sum(map_inputs, ga))
    parts.append(ga.sum().reshape(1))
    return torch.cat(parts)


def finish_uncertainty_step(state_theta: Tensor, features: Tensor, logits: Tensor, data_grad: Tensor,
                            data_loss: Tensor, involved: Tensor, params: UncertaintyParams,
                            map_inputs: Tensor | None = None) -> UncertaintyStepResult:
    """Add E_prior to the backend's data term, form g and take the step θ ← θ − λg − ηθ.

    logits (N, H, W); data_grad (N, HW) = ∂(γ_data·E_sim)/∂u; data_loss: 0-d tensor;
    involved (N,) bool = V.  Returns the new θ (float32) and E_uncer before the step.
    """
    n = logits.shape[0]
    flat = logits.reshape(n, -1)
    u = uncertainty_from_logits(flat, params.softplus_offset)
    scale = params.gamma_prior / involved.sum().clamp_min(1).float()
    prior_mask = involved.float().unsqueeze(1)
    prior_loss = (torch.log1p(u) * prior_mask).sum() * scale
    grad_u = data_grad + prior_mask * scale / (1.0 + u)
    g = theta_gradient(grad_u, uncertainty_slope(flat, params.softplus_offset), features, map_inputs)
    theta = state_theta.to(device=g.device, dtype=torch.float32)
    new_theta = theta - params.lr * g - params.weight_decay * theta
    return UncertaintyStepResult(theta=new_theta, loss=float(data_loss + prior_loss))
