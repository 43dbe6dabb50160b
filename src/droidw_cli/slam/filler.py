"""The trajectory filler: a pose for every input frame (DROID-SLAM's second pass).

For the frames between keyframes a and b (timestamps t_a ≤ t ≤ t_b):

1. geodesic SE(3) interpolation G(α) = Exp(α·Log(G_b G_a⁻¹)) G_a with
   α = (t − t_a)/(t_b − t_a);
2. a few motion-only BA iterations against both keyframes: edges a → t and
   b → t, targets from the correspondence source, the keyframes' poses and
   disparities fixed.  The keyframes' uncertainty enters as their BA
   confidence multiplier (DROID-W's clamp mapping), computed once over all
   keyframes and folded into the edge weights: rescaling u inside the filler's
   own small problem, whose other frames have no features, would normalise
   it against the wrong median.  The flow of each edge starts from
   the flow that the interpolated pose and the keyframe's disparity induce,
   so that frames far from both keyframes (keyframe removal leaves long gaps
   where the camera slows down) are still matched.

All frames of one gap are solved together in one batched BA.  Frames after
the last keyframe are extrapolated from it and refined against it alone.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from droidw_cli.ba.types import BAState, EdgeSet
from droidw_cli.slam.frontend import Frontend
from droidw_cli.slam.poses import interpolate


class TrajectoryFiller:
    """Collects frames between keyframes and solves their poses gap by gap."""

    def __init__(self, frontend: Frontend, iters: int, weight_factors: torch.Tensor | None = None,
                 correspondence=None):
        self.fe = frontend
        self.iters = iters
        self.weight_factors = weight_factors  # (K, h, w) uncertainty confidence multiplier per keyframe
        self.correspondence = correspondence if correspondence is not None else frontend.correspondence
        self.poses: dict[int, torch.Tensor] = {}  # frame position → world-to-camera (7,)
        self._kf_pos = {fi: k for k, fi in enumerate(frontend.buffer.frame_index)}
        self._pending: list[tuple[int, float, np.ndarray]] = []
        self._prev_kf: tuple[int, np.ndarray] | None = None

    def push(self, position: int, timestamp: float, image: np.ndarray) -> None:
        """Feed the frames of the second pass in order."""
        k = self._kf_pos.get(position)
        if k is None:
            self._pending.append((position, timestamp, image))
            return
        self.poses[position] = self.fe.buffer.poses[k].clone()
        self._solve(self._prev_kf, (k, image))
        self._prev_kf = (k, image)

    def finish(self) -> dict[int, torch.Tensor]:
        self._solve(self._prev_kf, None)
        return self.poses

    def _solve(self, a: tuple[int, np.ndarray] | None, b: tuple[int, np.ndarray] | None) -> None:
        frames, self._pending = self._pending, []
        if not frames:
            return
        buf = self.fe.buffer
        anchors = [x for x in (a, b) if x is not None]
        if not anchors:  # frames before the first keyframe (cannot happen: frame 0 is a keyframe)
            for pos, _, _ in frames:
                self.poses[pos] = torch.tensor([0, 0, 0, 0, 0, 0, 1.0])
            return
        ts = torch.tensor([t for _, t, _ in frames], dtype=torch.float64)
        if a is not None and b is not None:
            ta, tb = buf.timestamps[a[0]], buf.timestamps[b[0]]
            alpha = ((ts - ta) / max(tb - ta, 1e-9)).clamp(0, 1).float().to(buf.poses.device)
            init = interpolate(buf.poses[a[0]].expand(len(frames), 7), buf.poses[b[0]].expand(len(frames), 7), alpha)
        else:
            init = buf.poses[anchors[0][0]].expand(len(frames), 7).clone()
        if not self.fe.initialised or self.iters <= 0:
            for (pos, _, _), p in zip(frames, init):
                self.poses[pos] = p.clone()
            return
        poses = self._refine(anchors, frames, init)
        for (pos, _, _), p in zip(frames, poses):
            self.poses[pos] = p

    def _refine(self, anchors, frames, init: torch.Tensor) -> torch.Tensor:
        """Motion-only BA of the gap's frames against the anchor keyframes (fixed)."""
        fe, buf = self.fe, self.fe.buffer
        na, m = len(anchors), len(frames)
        kf = [k for k, _ in anchors]
        h, w = buf.grid
        dev = buf.device
        disps = torch.cat([buf.disps[kf], torch.ones(m, h, w, device=dev)])
        ii = torch.arange(na, device=dev).repeat_interleave(m)
        jj = na + torch.arange(m, device=dev).repeat(na)
        guess = BAState(torch.cat([buf.poses[kf], init]), disps, fe.shared.intrinsics.clone())
        coords, valid = fe.backend.reproject(guess, ii, jj, fe.params.min_depth)
        induced = coords.cpu() - fe.grid_coords
        targets, weights = [], []
        for e, (a, f) in enumerate(zip(ii.tolist(), jj.tolist())):
            kimg, img = anchors[a][1], frames[f - na][2]
            start = fe.full_res_flow(induced[e], valid[e].cpu(), img.shape[:2])
            c = self.correspondence.match(kimg, img, init_flow=start)
            targets.append(c.target)
            weight = c.weight
            if self.weight_factors is not None:
                weight = weight * self.weight_factors[kf[a]][..., None]
            weights.append(weight)
        edges = EdgeSet(ii, jj, torch.stack(targets).float().to(dev), torch.stack(weights).float().to(dev))
        state = BAState(torch.cat([buf.poses[kf], init]), disps, fe.shared.intrinsics.clone())
        params = dataclasses.replace(fe.params, t0=na, motion_only=True, optimize_focal="none",
                                     uncertainty=dataclasses.replace(fe.params.uncertainty, enable=False))
        for _ in range(self.iters):
            state = fe.backend.ba_step(state, edges, params).state
        return state.poses[na:]
