"""Frame-to-frame identities of dynamic objects (ADD-SLAM's dynamic object tracking, by mask overlap).

ADD-SLAM prompts the segmenter with each object's previous centre, frame by
frame, and ends a track at the border, on an area jump (> 1.5×) or a centre
jump (> 20 % of the view).  droidw tracks on keyframes several frames apart,
with noisy masks in which walkers that cross merge into one blob; there a
centre prompt picks the wrong walker and the jump rules end tracks that are
still in view (9-56 id switches per walker on the synthetic presets).  So
objects are associated by the overlap of their predicted masks, and the
ADD-SLAM rules guard only the weak matches (step 3).

Input per frame: the dynamic mask; optionally the depth D (≤ 0: unknown;
pass it only where it is measured, a depth sensor's) and the colour image.
*Components*: the 8-connected components of the mask that do not cross a depth
step (:func:`~droidw_cli.dynamics.association.depth_components`); those under
``min_area`` pixels are ignored.  A *live* track is an active one or a dormant
one (missed for at most ``max_missed`` frames).  Track t keeps a model: its
last fully seen mask M_t, centre c_t (inscribed circle of its largest part),
area a_t, median depth δ_t and colour histogram H_t (blended half and half
with each new full view).  The caller may give predicted centres c'_t (one
or several hypotheses, e.g. constant world velocity and still) and a
predicted depth δ'_t; else c'_t = c_t, δ'_t = δ_t.

1. Prediction: P_t = M_t shifted by round(c'_t − c_t); where the caller
   gives a mask carried by the image's flow (the object's pixels in the
   previous frame moved to their matches), P_t is that mask alone.  A track all of whose
   hypotheses fall outside the image has left the view: it ends ("left").
   A pixel *fits* the track when its depth is unknown or lies in
   [min(δ_t, δ'_t) / (1 + ``depth_tol``), max(δ_t, δ'_t) · (1 + ``depth_tol``)].
2. Claims: o_tc = |P_t ∩ C_c ∩ fit_t| for every component C_c; track t claims
   every C_c with o_tc / min(|P_t|, |C_c|) ≥ ``min_overlap`` (an object in
   several parts keeps one id).  Hypotheses are tried in order; a later one
   is used only by a track whose earlier ones claimed nothing, and only for
   components nothing claimed yet.  A component claimed by several tracks
   (walkers crossing) is split: each pixel goes to the track of least cost

       d(p, P_t) / ``split_px`` + |log(D_p / δ'_t)| / ``split_depth`` − ``split_colour`` · log H_t(I_p),

   averaged over a ``split_blur`` × ``split_blur`` window, among the tracks it
   fits (ties to the nearer track: it occludes the other).
   *Ground cue* (a depth sensor's runs): the caller may give each pixel's place
   G_p on the floor (2D coordinates in the plane normal to up; NaN: no depth)
   and each track's predicted place g'_t there.  Walkers that touch or overlap
   in the image stand apart on the floor: in the merged components of four
   synthetic RGB-D runs, each walker's own centroid on the floor labels 93-98 %
   of the two walkers' pixels right by the nearer centroid, against 83-91 % by
   the image centroids (their centroids lie 0.4 m apart, median).  Then track
   t also claims every C_c with
   |{p ∈ C_c : |G_p − g'_t| < ``ground_reach``}| / min(|P_t|, |C_c|) ≥ ``min_overlap``,
   and the split cost of a pixel is |G_p − g'_t| alone (0 without depth), unless
   two claimers' g'_t lie within ``ground_apart`` of each other: walkers in one
   place (the synthetic ones walk through each other) are split by the image
   cost above.
3. Fallback for a track that claimed nothing (ADD-SLAM's centre prompt): the
   unclaimed component containing round(c'_t), else the one whose centre is
   nearest to c'_t within ``max_jump · w``, kept only if its area is at most
   ``max_growth`` · a_t, its centre moved at most ``max_jump · w`` and half of
   its pixels fit the track.  A track whose claims gave it fewer than
   ``occluded`` · |P_t| pixels also takes, by the same rule, the nearest
   unclaimed component that would start a new track (step 5): a walker that a
   depth step cut in two keeps one id (stopgo RGB-D: 3 → 2 id switches, no
   other preset changed).  Then re-identification by appearance (large
   image motions, a missed keyframe): the unclaimed component of at least
   ``min_new`` of the view, within ``reid_reach · w`` of c'_t, with an area
   ratio within ``reid_area`` either way, half its pixels fitting, and the
   highest Bhattacharyya coefficient with H_t, at least ``reid_colour``; the
   unclaimed components that M_t moved onto it overlaps (as in step 2) join it.
4. A matched track's object is the union of its pixels.  It is *occluded* when
   it has fewer than ``occluded`` · |P_t| pixels: it keeps its id, but not its
   model (a half-hidden walker's mask and centre would mislead the next
   prediction).  An unmatched track becomes dormant; one dormant for more than
   ``max_missed`` frames ends ("lost").  Dormant tracks are matched like active
   ones, so an object that the masks miss for a frame or two gets its id back.
   No track ends at the border (ADD-SLAM's rule): a walker at the image edge
   stays in view, and keeps its id until its prediction leaves the image.
5. Unclaimed components of at least ``min_new`` of the view whose centre is
   not within ``border · w`` (x) or ``border · h`` (y) of the image border
   start new tracks with fresh ids (ADD-SLAM detects objects inside the view).

Backtracking to label earlier frames is left to the caller (the tracker keeps
no history).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import torch
from torch import Tensor

from droidw_cli.dynamics.association import (bhattacharyya, colour_bins, colour_histogram, depth_components,
                                             distance_to, median_depth, shift_mask)
from droidw_cli.dynamics.refine import make_objects, object_centre

Hypotheses = tuple[float, float] | list[tuple[float, float]]


@dataclass(frozen=True)
class TrackedObject:
    """One object in one frame: id, mask (h, w) bool numpy, centre (x, y), area (pixels), median depth
    of its pixels with a known depth (0: unknown), and whether it is mostly hidden (step 4)."""

    id: int
    mask: np.ndarray
    centre: tuple[float, float]
    area: int
    depth: float = 0.0
    occluded: bool = False


@dataclass(frozen=True)
class TrackEnd:
    """A finished track: its id, the frame at which it ended, and why (left/lost)."""

    id: int
    frame: int
    reason: str


@dataclass
class _Frame:
    """One frame's components and cues, shared by the steps of :meth:`DynamicObjectTracker.update`."""

    labels: np.ndarray  # (h, w) int, 0 background, 1…n components
    centres: np.ndarray  # (n, 2)
    areas: np.ndarray  # (n,)
    depth: np.ndarray | None
    bins: np.ndarray | None  # colour bin per pixel
    ground: np.ndarray | None = None  # (h, w, 2) places G_p on the floor (NaN: unknown)
    ground_pred: dict[int, np.ndarray] = field(default_factory=dict)  # id → predicted place g'_t
    _distances: dict[int, np.ndarray] = field(default_factory=dict)

    def ground_distance(self, tid: int) -> np.ndarray | None:
        """(h, w) |G_p − g'_t| on the floor (inf without depth); None without the cue."""
        if self.ground is None or tid not in self.ground_pred:
            return None
        if tid not in self._distances:
            d = np.linalg.norm(self.ground - self.ground_pred[tid], axis=-1)
            self._distances[tid] = np.where(np.isfinite(d), d, np.inf)
        return self._distances[tid]

    @property
    def n(self) -> int:
        return len(self.areas)

    def overlap(self, pred: np.ndarray, fit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Step 2 for a predicted mask: o_c = |pred ∩ fit ∩ C_c| and the score o_c / min(|pred|, |C_c|), (n,) each."""
        o = self.counts(pred & fit)
        return o, self.score(o, int(pred.sum()))

    def counts(self, pixels: np.ndarray) -> np.ndarray:
        """(n,) pixels of each component among ``pixels``."""
        return np.bincount(self.labels[pixels], minlength=self.n + 1)[1:].astype(np.float64)

    def score(self, o: np.ndarray, size: int) -> np.ndarray:
        """o_c / min(size, |C_c|): the overlap score of step 2 for a prediction of ``size`` pixels."""
        return o / np.maximum(np.minimum(size, self.areas), 1)


def _hypotheses(given: Hypotheses | None, centre: tuple[float, float]) -> list[tuple[float, float]]:
    """The predicted centres to try for a track: those given (one or a list), else its last centre."""
    if given is None or len(given) == 0:
        return [centre]
    return [tuple(given)] if np.isscalar(given[0]) else [tuple(c) for c in given]


def _moved(obj: TrackedObject, c: tuple[float, float]) -> np.ndarray:
    return shift_mask(obj.mask, int(round(c[0] - obj.centre[0])), int(round(c[1] - obj.centre[1])))


@dataclass
class DynamicObjectTracker:
    """Keeps object ids across frames; call :meth:`update` once per frame with its dynamic mask.

    The parameters are those of the module docstring; areas ``min_new`` are shares of the view.
    """

    border: float = 0.04
    max_growth: float = 1.5
    max_jump: float = 0.2
    min_area: int = 1
    min_new: float = 0.01
    min_overlap: float = 0.25
    max_missed: int = 2
    depth_tol: float = 0.7  # benchmarks/id_replay.py, RGB-D seeds 1-3: switches summed 41 at 0.5, 35 at 0.7 (no run
    #                         worse; seed 3, held out: 17 → 16), 37 at 0.6, 38 at 0.8 and 1.0 (docs/benchmarks.md)
    depth_step: float = 0.12  # id_replay.py, RGB-D captures of seeds 1-3 (2026-11-27): switches summed 41 at 0.15,
    #                          38 at 0.14, 35 at 0.13, 34 at 0.12 (no capture worse), 35 at 0.11, 36 at 0.10, 40 at
    #                          0.06 (docs/benchmarks.md, "Object ids: the depth step")
    occluded: float = 0.5  # id_replay.py, RGB-D captures of seeds 1-3 (default scenes): switches summed 21 at 0.5,
    #                       22 / 24 / 25 at 0.4 / 0.3 / 0.25 (docs/benchmarks.md, "Walkers that keep apart")
    split_px: float = 2.0
    split_depth: float = 0.1
    split_colour: float = 1.0
    split_blur: int = 5
    ground_reach: float = 0.5  # metres; id_replay.py, RGB-D seeds 1-3: switches 29 / 27 / 25 / 23 / 26 / 26 at
    #                             0.35 / 0.4 / 0.45 / 0.5 / 0.55 / 0.6
    ground_apart: float = 0.15  # metres; id_replay.py, RGB-D seeds 1-3 (seed 4): 23 (6) at 0 (the floor always),
    #                             23 (3) / 22 (3) / 21 (5) / 22 (5) / 22 (5) / 23 (5) at 0.05 / 0.1 / 0.15 / 0.2 /
    #                             0.25 / 0.35
    reid_colour: float = 0.85
    reid_reach: float = 0.6
    reid_area: float = 3.0
    active: dict[int, TrackedObject] = field(default_factory=dict)
    dormant: dict[int, tuple[TrackedObject, int]] = field(default_factory=dict)  # id → (model, frames missed)
    colours: dict[int, np.ndarray] = field(default_factory=dict)  # id → colour histogram H_t
    ended: list[TrackEnd] = field(default_factory=list)
    frame: int = -1
    _next_id: int = 0

    def live(self) -> dict[int, TrackedObject]:
        """Active and dormant tracks by id (their model)."""
        out = {tid: obj for tid, (obj, _) in self.dormant.items()}
        out.update(self.active)
        return dict(sorted(out.items()))

    def _at_border(self, centre, h: int, w: int) -> bool:
        x, y = float(centre[0]), float(centre[1])
        return min(x, w - 1 - x) < self.border * w or min(y, h - 1 - y) < self.border * h

    def _fit(self, f: _Frame, obj: TrackedObject, delta: float) -> np.ndarray:
        """Step 1: the pixels whose depth fits the track (all without depth)."""
        lo, hi = min(delta, obj.depth), max(delta, obj.depth)
        if f.depth is None or lo <= 0:
            return np.ones(f.labels.shape, bool)
        return (f.depth <= 0) | ((f.depth >= lo / (1 + self.depth_tol)) & (f.depth <= hi * (1 + self.depth_tol)))

    def _floor_apart(self, f: _Frame, owners: list[int]) -> bool:
        """Whether the claimers of a shared component all have predicted places on the floor, at least
        ``ground_apart`` from each other (else they stand in one place, and the floor cannot part them)."""
        if f.ground is None or any(t not in f.ground_pred for t in owners):
            return False
        g = [f.ground_pred[t] for t in owners]
        return all(np.linalg.norm(a - b) >= self.ground_apart for i, a in enumerate(g) for b in g[i + 1:])

    def _split_cost(self, tid: int, pred: np.ndarray, f: _Frame, delta: float, floor: bool = True) -> np.ndarray:
        """Step 2: the per-pixel cost of giving a shared component's pixels to track ``tid``."""
        ground = f.ground_distance(tid) if floor else None
        if ground is not None:
            return np.where(np.isfinite(ground), ground, 0.0)
        cost = distance_to(pred) / self.split_px
        if f.depth is not None and delta > 0:
            cost = cost + np.where(f.depth > 0, np.abs(np.log(np.maximum(f.depth, 1e-9) / delta)), 0.0) / self.split_depth
        if f.bins is not None and tid in self.colours:
            cost = cost - self.split_colour * np.log(self.colours[tid][f.bins])
        if self.split_blur > 1:
            cost = cv2.blur(cost.astype(np.float32), (self.split_blur, self.split_blur)).astype(np.float64)
        return cost

    def _object(self, tid: int, mask: np.ndarray, depth: np.ndarray | None, occluded: bool) -> TrackedObject:
        """The object of a track from its pixels: area, the inscribed-circle centre of its largest part, depth."""
        return TrackedObject(tid, mask, object_centre(mask), int(mask.sum()), median_depth(mask, depth),
                             bool(occluded))

    def _learn_colour(self, tid: int, mask: np.ndarray, bins: np.ndarray | None) -> None:
        if bins is not None and mask.any():
            hist = colour_histogram(bins, mask)
            self.colours[tid] = hist if tid not in self.colours else 0.5 * (self.colours[tid] + hist)

    def update(self, mask, predicted: dict[int, Hypotheses] | None = None, depth: np.ndarray | None = None,
               predicted_depth: dict[int, float] | None = None, image: np.ndarray | None = None,
               predicted_masks: dict[int, np.ndarray] | None = None, ground: np.ndarray | None = None,
               predicted_ground: dict[int, np.ndarray] | None = None) -> list[TrackedObject]:
        """Track the components of a (h, w) bool mask; returns this frame's objects, by id.

        ``predicted``: centre c'_t (or a list of hypotheses) of some live tracks in this frame;
        ``depth`` (h, w) (≤ 0: unknown) and ``predicted_depth`` δ'_t of some live tracks;
        ``image`` (h, w, 3) colour in [0, 1]; ``predicted_masks``: P_t of some live tracks carried by the
        image's flow (used instead of their centre hypotheses).  All optional (see the module docstring).
        """
        m = torch.as_tensor(np.asarray(mask.detach().cpu() if isinstance(mask, Tensor) else mask)).bool()
        if m.dim() != 2:
            raise ValueError(f"mask must be (h, w), got shape {tuple(m.shape)}")
        h, w = m.shape
        self.frame += 1
        predicted, predicted_depth = predicted or {}, predicted_depth or {}
        dep = None if depth is None else np.asarray(depth, dtype=np.float64).reshape(h, w)
        objs = make_objects(torch.from_numpy(depth_components(m.numpy(), dep, self.depth_step)), self.min_area)
        f = _Frame(objs.labels.numpy(), objs.centres.numpy(), objs.areas.numpy(), dep,
                   None if image is None else colour_bins(np.asarray(image).reshape(h, w, 3)),
                   None if ground is None else np.asarray(ground, dtype=np.float64).reshape(h, w, -1),
                   dict(predicted_ground or {}))
        live = self.live()
        missed = {tid: self.dormant[tid][1] if tid in self.dormant else 0 for tid in live}
        deltas = {tid: float(predicted_depth.get(tid, obj.depth)) for tid, obj in live.items()}
        fits = {tid: self._fit(f, obj, deltas[tid]) for tid, obj in live.items()}
        chosen = self._claims(f, live, predicted, fits, predicted_masks or {})
        pixels = self._split(f, chosen, fits, deltas)
        claimed = np.zeros(f.n, bool)
        for _, _, ok in chosen.values():
            claimed |= ok
        self._fallback_centre(f, live, chosen, fits, pixels, claimed)
        self._fallback_colour(f, live, chosen, fits, pixels, claimed)
        # 4. matched tracks (occluded ones keep their model), dormant tracks
        new_active: dict[int, TrackedObject] = {}
        new_dormant: dict[int, tuple[TrackedObject, int]] = {}
        out: list[TrackedObject] = []
        for tid, (_, pred, _) in chosen.items():
            if tid in pixels:
                occluded = pixels[tid].sum() < self.occluded * pred.sum()
                obj = self._object(tid, pixels[tid], dep, occluded)
                out.append(obj)
                new_active[tid] = live[tid] if occluded else obj
                if not occluded:
                    self._learn_colour(tid, obj.mask, f.bins)
            elif missed[tid] < self.max_missed:
                new_dormant[tid] = (live[tid], missed[tid] + 1)
            else:
                self.ended.append(TrackEnd(tid, self.frame, "lost"))
        # 5. new tracks
        for c in np.flatnonzero(~claimed):
            if not self._at_border(f.centres[c], h, w) and f.areas[c] >= self.min_new * h * w:
                comp = f.labels == c + 1
                obj = TrackedObject(self._next_id, comp, (float(f.centres[c, 0]), float(f.centres[c, 1])),
                                    int(f.areas[c]), median_depth(comp, dep))
                self._next_id += 1
                new_active[obj.id] = obj
                self._learn_colour(obj.id, comp, f.bins)
                out.append(obj)
        self.active, self.dormant = new_active, new_dormant
        return sorted(out, key=lambda o: o.id)

    def _claims(self, f: _Frame, live: dict[int, TrackedObject], predicted: dict[int, Hypotheses],
                fits: dict[int, np.ndarray], carried: dict[int, np.ndarray]
                ) -> dict[int, tuple[tuple[float, float], np.ndarray, np.ndarray]]:
        """Steps 1-2: per track still in view, (chosen c'_t, P_t, claims (n,) bool); ends the tracks that left."""
        cands: dict[int, list[tuple[tuple[float, float], np.ndarray]]] = {}
        for tid, obj in live.items():
            if tid in carried and carried[tid].any():  # the flow saw the object: no other hypothesis
                ys, xs = np.nonzero(carried[tid])
                cands[tid] = [((float(xs.mean()), float(ys.mean())), carried[tid])]
                continue
            cands[tid] = [(c, p) for c in _hypotheses(predicted.get(tid), obj.centre) if (p := _moved(obj, c)).any()]
            if not cands[tid]:
                del cands[tid]
                self.ended.append(TrackEnd(tid, self.frame, "left"))
        chosen: dict[int, tuple[tuple[float, float], np.ndarray, np.ndarray]] = {}
        taken = np.zeros(f.n, dtype=bool)
        for r in range(max((len(v) for v in cands.values()), default=0)):
            before = taken.copy()
            for tid, hyps in cands.items():
                if r >= len(hyps) or (tid in chosen and chosen[tid][2].any()):
                    continue
                c, p = hyps[r]
                ok = self._overlap_ok(f, p, fits[tid])
                if r > 0:  # a later hypothesis only for components no earlier one claimed
                    ok &= ~before
                if ok.any() or tid not in chosen:
                    chosen[tid] = (c, p, ok)
                    taken |= ok
        for tid, (c, p, ok) in chosen.items():  # ground claims: components near g'_t
            ground = f.ground_distance(tid)
            if ground is not None:
                near = f.counts(ground < self.ground_reach)
                chosen[tid] = (c, p, ok | (f.score(near, int(p.sum())) >= self.min_overlap))
        return chosen

    def _overlap_ok(self, f: _Frame, pred: np.ndarray, fit: np.ndarray) -> np.ndarray:
        return f.overlap(pred, fit)[1] >= self.min_overlap

    def _split(self, f: _Frame, chosen, fits: dict[int, np.ndarray], deltas: dict[int, float]) -> dict[int, np.ndarray]:
        """Step 2: the pixels of each track from its claimed components, shared components split by cost."""
        tids = list(chosen)
        pixels: dict[int, np.ndarray] = {}

        def give(tid: int, part: np.ndarray) -> None:
            pixels[tid] = pixels[tid] | part if tid in pixels else part

        for c in range(f.n):
            owners = [t for t in tids if chosen[t][2][c]]
            comp = f.labels == c + 1
            if len(owners) == 1:
                give(owners[0], comp)
            elif len(owners) > 1:  # ties to the nearer track (it occludes the other), then the larger overlap
                size = {t: f.overlap(chosen[t][1], fits[t])[0][c] for t in owners}
                owners.sort(key=lambda t: (deltas[t] if deltas[t] > 0 else np.inf, -size[t]))
                floor = self._floor_apart(f, owners)
                cost = np.stack([self._split_cost(t, chosen[t][1], f, deltas[t], floor) for t in owners])
                ok = np.stack([fits[t] for t in owners])
                cost = np.where(ok | ~ok.any(0), cost, np.inf)
                nearest = np.argmin(cost, axis=0)
                for j, t in enumerate(owners):
                    if (part := comp & (nearest == j)).any():
                        give(t, part)
        return pixels

    def _fallback_centre(self, f: _Frame, live, chosen, fits, pixels: dict[int, np.ndarray],
                         claimed: np.ndarray) -> None:
        """Step 3, ADD-SLAM's centre prompt, guarded by its area and jump rules."""
        h, w = f.labels.shape
        for tid, (c1, pred, _) in chosen.items():
            weak = tid in pixels and pixels[tid].sum() < self.occluded * pred.sum()
            if (tid in pixels and not weak) or f.n == 0:
                continue
            px, py = int(round(c1[0])), int(round(c1[1]))
            c = -1
            if 0 <= px < w and 0 <= py < h and f.labels[py, px] > 0 and not claimed[f.labels[py, px] - 1]:
                c = int(f.labels[py, px]) - 1
            else:
                dist = np.hypot(f.centres[:, 0] - c1[0], f.centres[:, 1] - c1[1])
                dist[claimed] = np.inf
                if weak:  # a partly seen track only takes a piece that would otherwise start a new track
                    dist[f.areas < self.min_new * h * w] = np.inf
                best = int(np.argmin(dist))
                if dist[best] <= self.max_jump * w:
                    c = best
            if c < 0:
                continue
            comp = f.labels == c + 1
            jump = float(np.hypot(f.centres[c, 0] - c1[0], f.centres[c, 1] - c1[1]))
            if (f.areas[c] <= self.max_growth * live[tid].area and jump <= self.max_jump * w
                    and (comp & fits[tid]).sum() >= 0.5 * f.areas[c]):
                claimed[c] = True
                pixels[tid] = pixels[tid] | comp if weak else comp

    def _fallback_colour(self, f: _Frame, live, chosen, fits, pixels: dict[int, np.ndarray],
                         claimed: np.ndarray) -> None:
        """Step 3, re-identification by appearance: the most alike unclaimed component, then the rest of the object."""
        if f.bins is None:
            return
        h, w = f.labels.shape
        pairs = []
        for tid, (c1, _, _) in chosen.items():
            if tid in pixels or tid not in self.colours:
                continue
            a = live[tid].area
            for c in np.flatnonzero(~claimed):
                comp = f.labels == c + 1
                jump = float(np.hypot(f.centres[c, 0] - c1[0], f.centres[c, 1] - c1[1]))
                if (f.areas[c] < self.min_new * h * w or jump > self.reid_reach * w
                        or max(f.areas[c] / max(a, 1), a / max(f.areas[c], 1)) > self.reid_area
                        or (comp & fits[tid]).sum() < 0.5 * f.areas[c]):
                    continue
                bc = bhattacharyya(self.colours[tid], colour_histogram(f.bins, comp))
                if bc >= self.reid_colour:
                    pairs.append((bc, tid, int(c)))
        for _, tid, c in sorted(pairs, reverse=True):
            if tid in pixels or claimed[c]:
                continue
            claimed[c] = True
            pixels[tid] = f.labels == c + 1
            more = ~claimed & self._overlap_ok(f, _moved(live[tid], tuple(f.centres[c])), fits[tid])
            for c2 in np.flatnonzero(more):
                claimed[c2] = True
                pixels[tid] |= f.labels == c2 + 1
