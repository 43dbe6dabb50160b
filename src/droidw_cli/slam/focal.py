"""When the focal length may move under ``--calib auto``, and how far.

With per-pixel disparities free, a camera that only translates leaves the
focal length unobservable.  Lateral translation t moves a pixel x at depth z by

    Δx = (f·t_xy − x·t_z) / z,

and f → a·f, t_xy → t_xy / a leaves every Δx unchanged (the depths absorb the
rest).  A small rotation ω adds a depth-free term (x, y relative to the principal point)

    Δx_rot = (x·y/f)·ω_x − (f + x²/f)·ω_y + y·ω_z,
    Δy_rot = (f + y²/f)·ω_x − (x·y/f)·ω_y − x·ω_z,

whose f and 1/f parts no depth can trade against: rotation ties f down, and
the more the orientations differ, the better.
A few keyframes with little motion (an initialisation from 3 keyframes, as the
parallax gate allows) fit a wrong f almost as well as the right one; the
focal step then trades against depth and pose, and on a real clip it ran
away to ~1 % of its starting value.  So f is

* fixed during initialisation;
* optimised in a window BA only when the window holds n ≥ ``min_keyframes``
  keyframes whose largest pairwise rotation

      θ_max = max_{i,j} ∠(R_i R_jᵀ) = max_{i,j} 2·atan2(‖v_ij‖, |w_ij|),
      q_ij = q_i ⊗ q_j⁻¹ = (v_ij, w_ij),

  is at least ``min_rotation`` degrees;
* clamped after every window to f ∈ [``focal_min``·f₀, ``focal_max``·f₀]
  (fx, fy each), f₀ the starting guess.
"""

from __future__ import annotations

import math

import torch
from torch import Tensor

from droidw_cli.config import CalibConfig
from droidw_cli.geometry.lie import quat_conjugate, quat_multiply, rotation_angle


def rotation_span(poses: Tensor) -> float:
    """θ_max in degrees: the largest rotation between any two of the poses (N, 7), all pairs at once."""
    if poses.shape[0] < 2:
        return 0.0
    q = poses[:, 3:].double()
    rel = quat_multiply(q[:, None, :].expand(-1, q.shape[0], -1), quat_conjugate(q)[None, :, :].expand(q.shape[0], -1, -1))
    return math.degrees(float(rotation_angle(rel).max()))


def focal_observable(poses: Tensor, cfg: CalibConfig) -> bool:
    """Whether a window with these keyframe poses (N, 7) constrains f (enough keyframes and rotation)."""
    return poses.shape[0] >= cfg.min_keyframes and rotation_span(poses) >= cfg.min_rotation


def clamp_focal(intrinsics: Tensor, focal0: float, cfg: CalibConfig) -> Tensor:
    """Intrinsics [fx, fy, cx, cy] with fx, fy clamped to [focal_min, focal_max]·f₀."""
    out = intrinsics.clone()
    out[0:2] = out[0:2].clamp(cfg.focal_min * focal0, cfg.focal_max * focal0)
    return out
