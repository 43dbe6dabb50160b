"""The trajectory filler: a pose for every input frame (DROID-SLAM's second pass).

For the frames between keyframes a and b (timestamps t_a ≤ t ≤ t_b):

1. geodesic SE(3) interpolation G(α) = Exp(α·Log(G_b G_a⁻¹)) G_a with
   α = (t − t_a)/(t_b − t_a);
2. a few motion-only BA iterations against both keyframes: edges a → t and
   b → t, targets from the correspondence source, the keyframes' poses and
   disparities (and uncertainty) fixed.

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

    def __init__(self, frontend: Frontend, iters: int, evidence: torch.Tensor | None = None):
        self.fe = frontend
        self.iters = iters
        self.evidence = evidence  # (K, M, h, w) keyframe evidence channels, when the map uses them
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
            alpha = ((ts - ta) / max(tb - ta, 1e-9)).clamp(0, 1).float()
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
        ii, jj, targets, weights = [], [], [], []
        for ai, (k, kimg) in enumerate(anchors):
            for fj, (_, _, img) in enumerate(frames):
                c = fe.correspondence.match(kimg, img, init_flow=None)
                ii.append(ai)
                jj.append(na + fj)
                targets.append(c.target)
                weights.append(c.weight)
        edges = EdgeSet(torch.tensor(ii), torch.tensor(jj), torch.stack(targets).float(), torch.stack(weights).float())
        h, w = buf.grid
        disps = torch.cat([buf.disps[kf], torch.ones(m, h, w)])
        feats = theta = extra = None
        unc = fe.params.uncertainty
        if unc.enable and buf.features is not None and fe.shared.theta is not None:
            c = buf.features.shape[1]
            feats = torch.cat([buf.features[kf].float(), torch.zeros(m, c, h, w)])
            theta = fe.shared.theta
            if self.evidence is not None:
                extra = torch.cat([self.evidence[kf], torch.zeros(m, self.evidence.shape[1], h, w)])
            elif unc.evidence:  # θ expects evidence inputs but none could be computed: neutral zeros
                extra = torch.zeros(len(kf) + m, theta.shape[0] - c - 1, h, w)
        state = BAState(torch.cat([buf.poses[kf], init]), disps, fe.shared.intrinsics.clone(), feats, theta,
                        map_inputs=extra)
        params = dataclasses.replace(fe.params, t0=na, motion_only=True, optimize_focal="none",
                                     uncertainty=dataclasses.replace(unc, bidirectional=False))
        for _ in range(self.iters):
            state = fe.backend.ba_step(state, edges, params).state
        return state.poses[na:]
