"""Typed inputs and outputs shared by every BA backend.

Conventions (all on the 1/8-resolution grid, H × W):

* ``poses``: (N, 7) float32, **world-to-camera** G_t, laid out as pypose's SE3
  ``[tx, ty, tz, qx, qy, qz, qw]`` (Hamilton quaternion, xyzw).
* ``disps``: (N, H, W) float32 inverse depth d_t of each pixel of keyframe t.
* ``intrinsics``: (4,) float32 ``[fx, fy, cx, cy]`` on the 1/8 grid; pixel
  (u, v) of the grid has its centre at x = u, y = v
  (see :func:`droidw_cli.geometry.camera.scale_intrinsics`).
* ``features``: (N, C, H, W) dense features F_t (float16 or float32).
* ``map_inputs``: optional (N, M, H, W) extra per-pixel inputs of the affine
  uncertainty map only (droidw's evidence channels, e.g. the multi-view flow
  residual); they take no part in the feature similarity s.
* ``theta``: (C + M + 1,) float32 affine map, u = softplus(θ·[F; X] + b), the
  bias b = θ[-1] last.
* ``depth_prior``: (N, H, W) prior *disparity* D_t; 0 where there is none.
* ``frame_ids``: (N,) int64 absolute keyframe indices, used only for the
  |i − j| ≥ min_frame_gap test of E_sim; None means positions 0..N−1.
* Edge k is directed (ii[k] → jj[k]): pixels of frame ii[k] are projected
  into frame jj[k].  ``target`` (E, H, W, 2) holds p*_ij as (x, y) grid
  coordinates in frame jj; ``weight`` (E, H, W, 2) the confidence w_ij ≥ 0.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import torch
from torch import Tensor


@dataclass(frozen=True)
class BAState:
    """The optimised variables of a window of keyframes (plus fixed inputs)."""

    poses: Tensor
    disps: Tensor
    intrinsics: Tensor
    features: Tensor | None = None
    theta: Tensor | None = None
    depth_prior: Tensor | None = None
    frame_ids: Tensor | None = None
    map_inputs: Tensor | None = None

    @property
    def num_frames(self) -> int:
        return int(self.poses.shape[0])

    @property
    def grid(self) -> tuple[int, int]:
        return int(self.disps.shape[1]), int(self.disps.shape[2])

    def with_(self, **changes) -> "BAState":
        """A copy with some fields replaced."""
        return replace(self, **changes)

    def to(self, device: torch.device | str) -> "BAState":
        """The same state on another device (None fields stay None)."""
        moved = {k: (v.to(device) if isinstance(v, Tensor) else v) for k, v in self.__dict__.items()}
        return BAState(**moved)

    def keyframe_ids(self) -> Tensor:
        """(N,) int64 absolute keyframe indices (``frame_ids`` or 0..N−1)."""
        if self.frame_ids is not None:
            return self.frame_ids.long()
        return torch.arange(self.num_frames, device=self.poses.device)


@dataclass(frozen=True)
class EdgeSet:
    """Directed frame-graph edges with their correspondence targets."""

    ii: Tensor
    jj: Tensor
    target: Tensor
    weight: Tensor

    @property
    def num_edges(self) -> int:
        return int(self.ii.shape[0])

    def to(self, device: torch.device | str) -> "EdgeSet":
        return EdgeSet(self.ii.to(device), self.jj.to(device), self.target.to(device), self.weight.to(device))


@dataclass(frozen=True)
class BAStepResult:
    """The outcome of one Gauss-Newton iteration.

    Attributes:
        state: the updated state (poses, disps and, if optimised, intrinsics).
        cost: the weighted squared reprojection error before the step.
        solved: False when the Cholesky factorisation failed (the step is zero).
    """

    state: BAState
    cost: float
    solved: bool


@dataclass(frozen=True)
class UncertaintyStepResult:
    """The outcome of one gradient step on θ (DROID-W Eq. 9).

    Attributes:
        theta: the updated affine weights, (C + 1,).
        loss: E_uncer = γ_data·E_sim + γ_prior·E_prior before the step.
    """

    theta: Tensor
    loss: float
