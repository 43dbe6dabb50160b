"""The trajectory filler: a pose for every input frame, online, in the same pass.

DROID-SLAM fills in the non-keyframes in a second pass over the video (flow
against the two neighbouring keyframes, motion-only BA).  droidw does it in
the first pass, with no second decode: every frame t keeps its grey working
image until the keyframe gap (a, b) around it can be solved, that is once a
is ``lag`` keyframes old (its depth has had a few window BA rounds).  Then,
for all frames of the gap at once:

1. the geodesic SE(3) interpolation G_t = Exp(α · Log(G_b G_a⁻¹)) G_a,
   α = (t − t_a) / (t_b − t_a), as the starting pose;
2. the correspondence source's cheap targets a → t and b → t
   (:meth:`~droidw_cli.correspondence.base.CorrespondenceSource.quick_target`;
   for DIS one flow at the working resolution with ``correspondence.quick_preset``
   ("fine": FAST with its finest level at 1/2 size and no variational refinement; FAST
   left the 600-frame static control at 0.51 cm, fine 0.34), area-averaged onto the grid:
   p*_at = p + f̄_at / 8);
3. ``iters`` motion-only BA iterations (Eq. 4 with the keyframes' poses and
   disparities fixed), each pixel weighted by its keyframe's BA confidence,
   its uncertainty weight (DROID-W's clamp mapping, ``relative`` level over
   the keyframe) and a Cauchy weight of its residual, re-evaluated every
   iteration (IRLS), which keeps movers that the uncertainty missed from
   pulling the pose:
   w = w_k · 1 / (1 + (r / σ)²),  r = ‖p*_kt − Π(G_t G_k⁻¹ Π⁻¹(p, d_k))‖ in grid px;
4. model selection: with ρ the ratio of the refined pose's mean robust cost
   log(1 + (r/σ)²) to the interpolation's, the frame takes
   Exp(λ · Log(G_ref G_int⁻¹)) G_int, λ = clamp((``blend_gain`` − ρ) /
   (``blend_gain`` − ``min_gain``), 0, 1): the refined pose where the flow
   explains it clearly better, the interpolation where it hardly does.  A
   near-still camera that wobbles smoothly is interpolated almost exactly, and
   the flow against its keyframes' young depths only adds noise.  On the
   generator's 450-frame presets: wobble 0.56 cm interpolated, 0.93 cm always
   refined, 0.67 cm with a hard cut at 0.5; walk 1.23 cm interpolated, 1.04-1.05
   cm refined either way.  The hard cut at 0.5 left stop-and-go frames whose
   refinement reached ρ 0.54-0.86 at their interpolation, 0.6-1.0 cm off; the blend
   0.4-0.8 took RGB-D (SE(3)) stopgo seed 2 0.221 → 0.203 cm and monocular
   (Sim(3)) 0.174 → 0.151, wobble unchanged (0.240; a cut at 0.8: 0.301).  A refined camera
   centre that leaves the interpolated one by more than ``max_departure`` of
   the distance between the gap's keyframes is a failed refinement and is not
   kept (single frames 1-2.5 cm off on the near-still wobble: 0.61 → 0.39 cm RGB-D);
5. ``smooth`` passes of [1 2 1]/4 over time on the gap's departures Log(G_t G_int,t⁻¹)
   (:func:`smooth_departures`): 0-14 % lower ATE on the 14 runs measured, none higher.

With ``stride`` s > 1 only every s-th frame after a gap's keyframe keeps its grey image and is
measured (steps 2-5); the others take the departure Log(G_t G_int,t⁻¹) interpolated linearly
in time between their measured neighbours, zero at the keyframes (:func:`between_departures`).
Since the departures are smooth within a gap, ``fast`` measured every 2nd frame with the finer
flow at the cost of the coarser one on every frame, and its ATE fell (``configs/fast.yaml``).

Both sides matter: against a alone the camera centre of a frame a few frames
away is poorly conditioned (rotation and translation trade off), 2 cm median
error on the generator's static walk with exact depth, against 0.3 cm with
both keyframes and 1.0 cm for the interpolation alone.

A frame keeps only its poses relative to the two keyframes of its gap,
R_ta = G_t G_a⁻¹ and R_tb = G_t G_b⁻¹, and its final pose blends their
compositions with the keyframes' final poses (after the global BA):

    G_t = Exp(α · Log((R_tb G_b) (R_ta G_a)⁻¹)) · R_ta G_a,

so when the BA later moves a and b relative to each other, the correction is
spread over the gap instead of being carried from a alone.  (On the walk at
600 frames, one-sided anchoring right after initialisation left 16-27 cm
errors in a gap whose far keyframe moved afterwards.)

Keyframe removal drops the second-newest keyframe r right after the newest
has had its first BA iterations.  The removed keyframe becomes a frame between
its predecessor and its successor, at its window-BA pose relative to them, and
its gap's frames join the predecessor's gap, which is still open (it is one
keyframe old, younger than ``lag``): they are solved later, against keyframes
whose poses and depths have settled, and their starting poses interpolate
piecewise through r (a "knot").  Solving r's gap at removal, against a
successor only one BA round old, left single frames 2-4 cm off on the RGB-D
walk (seed 1, 450 frames: SE(3) ATE 0.63 → 0.54 cm; straight interpolation
across the merged gap instead of through the knot: stopgo 0.35 → 0.39 cm).
Every pose is resolved from keyframes that outlived it, so the dependencies
have no cycle.
Memory: the grey images of the frames not yet solved (a few gaps) plus two
7-vectors per frame, kept in one table (:class:`AnchorTable`, about 180 bytes a
frame; two separate tensors per frame cost about 1.2 KB, 21 MB for a 10-minute video).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from droidw_cli.ba.types import BAState, EdgeSet
from droidw_cli.ba.uncertainty import uncertainty_map, weight_factor, weighting_input
from droidw_cli.config import FillerConfig
from droidw_cli.geometry.poses import compose, interpolate, invert, log_departure, retract
from droidw_cli.slam.evidence import evidence_maps
from droidw_cli.slam.filler_flow import AheadTargets, grey
from droidw_cli.slam.optimizer import window_state

IDENTITY = torch.tensor([0, 0, 0, 0, 0, 0, 1.0])


@dataclass
class _Pending:
    frame_index: int
    timestamp: float
    image: np.ndarray | None  # grey working image; None: interpolate only


@dataclass
class _Anchored:
    """G_t relative to the keyframes a (frame index) and, when it exists, b: R_ta, R_tb and α."""

    a: int
    rel_a: Tensor
    b: int | None = None
    rel_b: Tensor | None = None
    alpha: float = 0.0


class AnchorTable:
    """Frame index → :class:`_Anchored`, stored as rows of one tensor (the relative poses) and arrays.

    R_ta and R_tb of every frame live in one growable (capacity, 2, 7) tensor on
    the device and dtype of the first pose stored; a, b (−1: none) and α in numpy
    arrays.  :meth:`get` hands out an :class:`_Anchored` whose poses are views
    of the table's rows, with the values that were put.
    """

    def __init__(self) -> None:
        self._row: dict[int, int] = {}
        self._poses: Tensor | None = None
        self._a = np.empty(0, np.int64)
        self._b = np.empty(0, np.int64)
        self._alpha = np.empty(0, np.float64)

    def __len__(self) -> int:
        return len(self._row)

    def __contains__(self, frame: int) -> bool:
        return frame in self._row

    def __iter__(self):
        return iter(self._row)

    @property
    def nbytes(self) -> int:
        poses = 0 if self._poses is None else self._poses.element_size() * self._poses.nelement()
        return poses + self._a.nbytes + self._b.nbytes + self._alpha.nbytes

    def _grow(self, like: Tensor) -> None:
        old = len(self._a)
        new = max(old + 1024, int(old * 1.25))
        poses = torch.zeros(new, 2, 7, dtype=like.dtype, device=like.device)
        if self._poses is not None:
            poses[:old] = self._poses
        self._poses = poses
        self._a, self._b, self._alpha = (np.concatenate([v, np.zeros(new - old, v.dtype)])
                                         for v in (self._a, self._b, self._alpha))

    def __setitem__(self, frame: int, rec: _Anchored) -> None:
        row = self._row.get(frame)
        if row is None:
            row = len(self._row)
            if row == len(self._a):
                self._grow(rec.rel_a)
            self._row[frame] = row
        self._poses[row, 0] = rec.rel_a
        if rec.b is not None:
            self._poses[row, 1] = rec.rel_b
        self._a[row], self._b[row], self._alpha[row] = rec.a, -1 if rec.b is None else rec.b, rec.alpha

    def get(self, frame: int) -> _Anchored | None:
        row = self._row.get(frame)
        if row is None:
            return None
        b = int(self._b[row])
        if b < 0:
            return _Anchored(int(self._a[row]), self._poses[row, 0], alpha=float(self._alpha[row]))
        return _Anchored(int(self._a[row]), self._poses[row, 0], b, self._poses[row, 1], float(self._alpha[row]))


class TrajectoryFiller:
    """Gives every non-keyframe a pose relative to a keyframe; composes them at the end."""

    def __init__(self, frontend, cfg: FillerConfig, max_pending: int = 150):
        self.fe = frontend
        self.cfg = cfg
        self.max_pending = max_pending  # frames with an image kept before initialisation (memory bound)
        self._pending: dict[int, list[_Pending]] = {}  # anchor frame index → frames after it
        self._relative = AnchorTable()  # frame index → its poses relative to its gap's keyframes
        self._stored = 0
        self._targets = AheadTargets(frontend.correspondence)  # the flows a → t and b → t, on a worker
        self._knots: dict[int, dict[int, float]] = {}  # anchor frame index → {removed keyframe in its gap: timestamp}

    # ---------------------------------------------------------------- feeding
    def add_frame(self, frame_index: int, timestamp: float, anchor: int, image: np.ndarray) -> None:
        """A non-keyframe (working-resolution image) that follows keyframe ``anchor`` (a frame index).
        Only every ``stride``-th frame after its anchor keeps its image to be measured."""
        gap = self._pending.setdefault(anchor, [])
        skipped = (len(gap) + 1) % self.cfg.stride != 0
        kept = None if skipped or (not self.fe.initialised and self._stored >= self.max_pending) else grey(image)
        self._stored += kept is not None
        gap.append(_Pending(frame_index, timestamp, kept))
        buf = self.fe.buffer
        k = len(buf) - 1
        if kept is not None and self.fe.initialised and self.cfg.iters > 0 and buf.frame_index[k] == anchor:
            self._targets.submit(anchor, self.fe.images[k], frame_index, kept)

    def keyframe_removed(self, k: int) -> None:
        """Keyframe removal is about to drop buffer index k (≥ 1): anchor it to k − 1 and k + 1, and merge
        its gap into k − 1's while that is open (else solve it now)."""
        buf = self.fe.buffer
        fr = buf.frame_index[k]
        prev = buf.frame_index[k - 1]
        # the last update saw len(buf) - 2 as the newest keyframe: gap k - 1 is still open if it was younger than lag
        if self.fe.initialised and (len(buf) - 2) - (k - 1) < self.cfg.lag:
            frames = self._pending.pop(fr, [])
            self._pending.setdefault(prev, []).extend(frames)
            self._knots.setdefault(prev, {}).update({**self._knots.pop(fr, {}), fr: buf.timestamps[k]})
            if self.cfg.iters > 0:
                for p in frames:
                    if p.image is not None:
                        self._targets.submit(prev, self.fe.images[k - 1], p.frame_index, p.image)
        else:
            self._solve(k)
        self._relative[fr] = self._anchored(buf.poses[k], buf.timestamps[k], k - 1, k + 1)

    def update(self) -> None:
        """After each keyframe: solve the gaps whose anchor is at least ``lag`` keyframes old."""
        if not self.fe.initialised:
            return
        buf = self.fe.buffer
        newest = len(buf) - 1
        position = {f: k for k, f in enumerate(buf.frame_index)}
        for anchor in sorted(self._pending):
            k = position.get(anchor)
            if k is not None and newest - k >= self.cfg.lag:
                self._solve(k)
        if self.cfg.iters <= 0:
            return
        for anchor, frames in self._pending.items():  # start the flows b → t of the gaps that now have a b
            k = position.get(anchor)
            if k is not None and k + 1 < len(buf) and k + 1 in self.fe.images:
                for p in frames:
                    if p.image is not None:
                        self._targets.submit(buf.frame_index[k + 1], self.fe.images[k + 1], p.frame_index, p.image)

    def finish(self) -> dict[int, Tensor]:
        """Solve what is left and return world-to-camera poses of every frame (keyframes included)."""
        buf = self.fe.buffer
        position = {f: k for k, f in enumerate(buf.frame_index)}
        if self.fe.initialised:
            for anchor in sorted(self._pending):
                if anchor in position:
                    self._solve(position[anchor])
        poses = {f: buf.poses[k].clone() for f, k in position.items()}
        ident = IDENTITY.to(buf.device, copy=True)
        for anchor, frames in self._pending.items():  # never initialised: everything at its anchor
            for p in frames:
                self._relative[p.frame_index] = _Anchored(anchor, ident.clone())
        self._pending.clear()
        self.close()
        for f in sorted(self._relative):
            self._resolve(f, poses, ident)
        return poses

    def close(self) -> None:
        """Stop the flow worker (later solves compute their flows synchronously)."""
        self._targets.close()

    def _resolve(self, f: int, poses: dict[int, Tensor], ident: Tensor) -> None:
        """poses[f] from its keyframes' final poses, resolving removed keyframes first (explicit stack)."""
        stack = [f]
        while stack:
            g = stack[-1]
            if g in poses:
                stack.pop()
                continue
            rec = self._relative.get(g)
            if rec is None or g in (rec.a, rec.b):  # an anchor that was never recorded: stays at the identity
                poses[g] = ident.clone()
                stack.pop()
                continue
            missing = [x for x in (rec.a, rec.b) if x is not None and x not in poses]
            if missing:
                stack += missing
                continue
            via_a = compose(rec.rel_a, poses[rec.a])
            if rec.b is None:
                poses[g] = via_a
            else:
                via_b = compose(rec.rel_b, poses[rec.b])
                alpha = torch.tensor([rec.alpha], dtype=via_a.dtype, device=via_a.device)
                poses[g] = interpolate(via_a[None], via_b[None], alpha)[0]
            stack.pop()

    def _anchored(self, pose: Tensor, timestamp: float, k: int, kb: int) -> _Anchored:
        """A pose G_t (world-to-camera) between buffer keyframes k and kb (when it exists) as an _Anchored."""
        buf = self.fe.buffer
        rec = _Anchored(buf.frame_index[k], compose(pose, invert(buf.poses[k])))
        if kb < len(buf):
            ta, tb = buf.timestamps[k], buf.timestamps[kb]
            rec.b = buf.frame_index[kb]
            rec.rel_b = compose(pose, invert(buf.poses[kb]))
            rec.alpha = float(min(max((timestamp - ta) / max(tb - ta, 1e-9), 0.0), 1.0))
        return rec

    # ---------------------------------------------------------------- solving
    def _solve(self, k: int) -> None:
        """Solve the gap after keyframe k (buffer index) and keep its frames' relative poses."""
        buf = self.fe.buffer
        frames = self._pending.pop(buf.frame_index[k], [])
        knots = self._knots.pop(buf.frame_index[k], {})
        if not frames:
            return
        self._stored -= sum(p.image is not None for p in frames)
        ts = torch.tensor([p.timestamp for p in frames], dtype=torch.float64)
        pose_a = buf.poses[k]
        if k + 1 < len(buf):
            init = self._interpolate(k, knots, ts)
        else:
            init = pose_a.expand(len(frames), 7).clone()
        measured = [n for n, p in enumerate(frames) if p.image is not None]
        if measured and self.cfg.iters > 0:
            anchors = [k] + ([k + 1] if k + 1 < len(buf) else [])
            refined = self._refine(anchors, [frames[n] for n in measured], init[measured])
            if len(measured) < len(frames):
                init = between_departures(init, refined, measured, ts, buf.timestamps[k],
                                          buf.timestamps[k + 1] if k + 1 < len(buf) else None)
            init[measured] = refined
        self._targets.forget(p.frame_index for p in frames)
        for p, pose in zip(frames, init):
            self._relative[p.frame_index] = self._anchored(pose, p.timestamp, k, k + 1)

    def _interpolate(self, k: int, knots: dict[int, float], ts: Tensor) -> Tensor:
        """(m, 7) starting poses of gap (k, k + 1) at timestamps ``ts``: geodesic interpolation,
        piecewise through the removed keyframes merged into the gap (``knots``: frame index →
        timestamp), each at its window-BA pose relative to its neighbours composed with their
        current poses."""
        buf = self.fe.buffer
        a, b = buf.frame_index[k], buf.frame_index[k + 1]
        poses = {a: buf.poses[k], b: buf.poses[k + 1]}
        ident = IDENTITY.to(buf.device, copy=True)
        for f in knots:
            self._resolve(f, poses, ident)
        stamps = {a: buf.timestamps[k], b: buf.timestamps[k + 1], **knots}
        order = sorted(stamps, key=stamps.get)
        knot_t = torch.tensor([stamps[f] for f in order], dtype=torch.float64)
        knot_pose = torch.stack([poses[f] for f in order])
        seg, alpha = knot_segments(knot_t, ts)
        return interpolate(knot_pose[seg], knot_pose[seg + 1], alpha.float().to(buf.device))

    def anchor_weight(self, k: int) -> Tensor:
        """(h, w) per-pixel weight of keyframe k as an anchor: BA confidence × uncertainty factor."""
        fe, buf = self.fe, self.fe.buffer
        mine = [(i, j) for (i, j) in fe.cache.pairs() if i == k]
        if not mine:
            return torch.ones(buf.grid, device=buf.device)
        conf = torch.stack([fe.cache.weight(p)[..., 0].float() for p in mine]).mean(0)
        unc = fe.params.uncertainty
        theta = fe.shared.theta
        if not (self.cfg.uncertainty and unc.enable and buf.features is not None and theta is not None):
            return conf
        lo = min(k, min(j for _, j in mine))
        hi = max(k, max(j for _, j in mine)) + 1
        state = window_state(buf, lo, hi, fe.shared, with_features=False)
        evidence = None
        if unc.evidence:
            edges = fe.cache.edge_set(mine, offset=lo)
            evidence = evidence_maps(fe.backend, state, edges, fe.params.min_depth)[k - lo: k - lo + 1]
        u = uncertainty_map(buf.feature_block(k, k + 1).float(), theta, unc.softplus_offset, evidence)
        return conf * weight_factor(weighting_input(u, fe.cfg.uncertainty.mode), fe.cfg.uncertainty.mode)[0]

    def _refine(self, anchors: list[int], frames: list[_Pending], init: Tensor) -> Tensor:
        """Motion-only IRLS BA of m frames against the anchor keyframes (fixed): (m, 7) world-to-camera poses."""
        fe, buf = self.fe, self.fe.buffer
        m, na = len(init), len(anchors)
        h, w = buf.grid
        pairs = [(buf.frame_index[k], fe.images[k], p.frame_index, p.image) for k in anchors for p in frames]
        target = torch.stack(self._targets.get(pairs)).float().to(buf.device)
        inside = ((target[..., 0] >= 0) & (target[..., 0] <= w - 1) & (target[..., 1] >= 0) & (target[..., 1] <= h - 1))
        base = torch.stack([self.anchor_weight(k) for k in anchors]).repeat_interleave(m, 0) * inside.float()
        ii = torch.arange(na, device=buf.device).repeat_interleave(m)
        jj = na + torch.arange(m, device=buf.device).repeat(na)
        disps = torch.cat([buf.disps[anchors], torch.ones(m, h, w, device=buf.device)])
        state = BAState(torch.cat([buf.poses[anchors], init]), disps, fe.shared.intrinsics.clone())
        params = dataclasses.replace(fe.params, t0=na, motion_only=True, optimize_focal="none",
                                     uncertainty=dataclasses.replace(fe.params.uncertainty, enable=False))
        sigma = self.cfg.robust_sigma

        def residual(st: BAState) -> tuple[Tensor, Tensor]:
            coords, valid = fe.backend.reproject(st, ii, jj, fe.params.min_depth)
            r = torch.hypot(target[..., 0] - coords[..., 0], target[..., 1] - coords[..., 1])
            return r, base * valid.float()

        def robust_cost(r: Tensor, w: Tensor) -> Tensor:  # per frame: Σ w log(1 + (r/σ)²) / Σ w
            num = (w * torch.log1p((r / sigma) ** 2)).sum((1, 2)).view(na, m).sum(0)
            return num / w.sum((1, 2)).view(na, m).sum(0).clamp_min(1e-9)

        start = None
        for _ in range(self.cfg.iters):
            r, w_valid = residual(state)
            if start is None:
                start = robust_cost(r, w_valid)
            edges = EdgeSet(ii, jj, target, (w_valid / (1.0 + (r / sigma) ** 2))[..., None].expand(-1, h, w, 2).contiguous())
            state = fe.backend.ba_step(state, edges, params).state
        final = robust_cost(*residual(state))
        share = self._refined_share(final, start)
        if self.cfg.max_departure > 0 and na == 2:
            # a refined camera centre that leaves the interpolated one by more than a share of the
            # gap's keyframe baseline is a failed refinement, not the camera's motion
            centres = invert(state.poses)[:, :3]
            baseline = (centres[1] - centres[0]).norm()
            departure = (invert(state.poses[na:])[:, :3] - invert(init)[:, :3]).norm(dim=1)
            share = torch.where(departure <= self.cfg.max_departure * baseline, share, torch.zeros_like(share))
        return smooth_departures(init, interpolate(init, state.poses[na:], share), self.cfg.smooth, closed=na == 2)

    def _refined_share(self, final: Tensor, start: Tensor) -> Tensor:
        """(m,) λ ∈ [0, 1] of the refined pose in the geodesic blend with the interpolation (model selection):
        1 where the cost ratio ρ = final / start ≤ ``min_gain``, 0 where ρ ≥ ``blend_gain``, linear between."""
        lo, hi = self.cfg.min_gain, self.cfg.blend_gain
        ratio = torch.where(start > 0, final / start.clamp_min(1e-12), torch.ones_like(start))
        if hi <= lo:
            return (ratio < lo).to(final.dtype)
        return ((hi - ratio) / (hi - lo)).clamp(0.0, 1.0)


def smooth_departures(init: Tensor, poses: Tensor, passes: int, closed: bool) -> Tensor:
    """A gap's poses (m, 7), in time order, with their departures from its interpolation ``init`` smoothed over time.

    δ_t = Log(G_t G_int,t⁻¹); each pass replaces δ_t by (δ_{t−1} + 2 δ_t + δ_{t+1}) / 4, with δ = 0 at the
    gap's keyframes (both ends when ``closed``, else the last frame repeated), and G_t = Exp(δ_t) G_int,t.
    The refined departures err smoothly within a gap more than from frame to frame, so one pass gains a
    little everywhere measured (docs/benchmarks.md, "What the filler adds to the error").
    """
    if passes <= 0 or len(poses) < 2:
        return poses
    delta = log_departure(poses, init)
    zero = torch.zeros_like(delta[:1])
    for _ in range(passes):
        left = torch.cat([zero, delta[:-1]])
        right = torch.cat([delta[1:], zero if closed else delta[-1:]])
        delta = 0.25 * left + 0.5 * delta + 0.25 * right
    return retract(delta, init)


def between_departures(init: Tensor, refined: Tensor, measured: list[int], ts: Tensor, t_a: float,
                       t_b: float | None) -> Tensor:
    """A gap's poses (m, 7) where only the frames ``measured`` were refined (``filler.stride``): the others
    take their departure Log(G G_int⁻¹) interpolated linearly in time between their measured neighbours,
    with zero departure at the gap's keyframes (at t_a, and at t_b when the gap is closed; an open gap
    holds its last measured departure).  Returns the gap's poses with the measured ones left as ``init``."""
    delta = log_departure(refined, init[measured]).double().cpu()  # the knots live on the host, with ts
    stamps = ts[measured].double()
    zero = torch.zeros(1, 6, dtype=torch.float64)
    knots_t = torch.cat([torch.tensor([t_a], dtype=torch.float64), stamps]
                        + ([torch.tensor([t_b], dtype=torch.float64)] if t_b is not None else []))
    knots_d = torch.cat([zero, delta] + ([zero] if t_b is not None else []))
    kept = set(measured)
    other = [n for n in range(len(init)) if n not in kept]
    seg, alpha = knot_segments(knots_t, ts[other].double())
    alpha = alpha[:, None]
    out = init.clone()
    out[other] = retract(((1 - alpha) * knots_d[seg] + alpha * knots_d[seg + 1]).to(init), init[other])
    return out


def knot_segments(knot_t: Tensor, ts: Tensor) -> tuple[Tensor, Tensor]:
    """For times ``ts``, the segment s of the sorted knot times (knot_t[s] ≤ t < knot_t[s + 1], clamped to
    the first and last) and the position α = (t − t_s) / (t_{s+1} − t_s) in it, clamped to [0, 1]."""
    seg = (torch.searchsorted(knot_t, ts, right=True) - 1).clamp(0, len(knot_t) - 2)
    t0, t1 = knot_t[seg], knot_t[seg + 1]
    return seg, ((ts - t0) / (t1 - t0).clamp_min(1e-9)).clamp(0.0, 1.0)
