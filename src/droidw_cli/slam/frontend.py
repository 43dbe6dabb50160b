"""The frontend: initialisation and sliding-window local BA (DROID-SLAM skeleton).

Every flow threshold is in pixels of the 1/8 grid (:mod:`droidw_cli.slam.distance`).

* Initialisation once ``warmup_min`` keyframes show ``init_parallax`` grid px of
  parallax that no homography explains (:mod:`droidw_cli.slam.parallax`), or
  at ``warmup`` keyframes whatever the parallax.  The keyframes are brought
  in one at a time (constant-velocity pose guess) with a few BA iterations
  each, then ``init_iters`` iterations over all of them; the first three
  start from a two-view model of keyframes 0 and 2 (:mod:`droidw_cli.slam.two_view`)
  unless a homography explains that pair as well, where every pose starts at
  the identity and every disparity at 1 (a camera walking into the scene
  took the flat start for a sideways step: 58° off on the ``forward`` preset).  A fixed camera never
  gets a second keyframe (the motion filter tests the median flow before
  initialisation), so it stays at the identity.
* Under ``--calib auto`` the focal length stays fixed during initialisation and
  is optimised in a window only once its keyframes show enough rotation to
  constrain it, within bounds (:mod:`droidw_cli.slam.focal`).
* Update for each later keyframe k, which starts at the damped
  constant-velocity pose and its predecessor's disparity warped into it, then
  is placed against its predecessor alone (:mod:`droidw_cli.slam.placement`):
  edges to its ``radius`` predecessors plus proximity edges of the newest
  keyframes inside the window (the newest ``window`` keyframes, widened up to
  ``window_max`` while they reach fewer than ``window_span`` input frames back:
  fast rotation) (frame distance under ``flow_thresh``, with
  non-maximum suppression ``nms``); edges older than ``max_age`` BA
  iterations leave the window; at most ``max_edges``.  ``iters1``
  iterations, then *keyframe removal*: when the two keyframes before k are
  less than ``keyframe_thresh`` apart, the second-newest is removed with its
  edges and the second round of ``iters2`` iterations is skipped, so a camera
  that slows down or stops adds no keyframes.  The oldest two keyframes of a
  window that does not start at 0 stay fixed (gauge and scale); of the
  window's edges, rather: the oldest two keyframes they still reach.
* With the uncertainty on (and ``dynamics.mode`` epipolar|both), every edge loses the
  pixels of its keyframe that the dominant epipolar geometry cannot explain
  (:mod:`droidw_cli.dynamics.epipolar`).  The learned uncertainty reads the
  map, so it cannot find movers that the map was built on: during
  initialisation, or when a mover walks in.
* With ``dynamics.mode`` consistency|both, each keyframe also loses the pixels
  of its scene-consistency objects (:mod:`droidw_cli.dynamics.inloop`),
  detected for the initial keyframes after initialisation and for each new
  keyframe after its first ``iters1`` iterations.

The keyframe buffer, the edge cache, θ and the intrinsics live on the BA backend's device
(``backend.device``); images and DIS flow stay on the host, and each edge's target and confidence
are copied to the device once, when they are cached.  The new edges of a keyframe are matched, each
with its epipolar distance map, in one
:meth:`~droidw_cli.correspondence.base.CorrespondenceSource.match_all` call, on as many threads as
there are cores when the source allows it (each flow started as :mod:`droidw_cli.slam.starts` says); the
pair (k, k − 1), started from the motion filter's flow, usually comes ready from the scout (:mod:`droidw_cli.slam.scout`), which matched it on another thread
during the previous keyframe's BA.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from droidw_cli.ba.interface import BABackend
from droidw_cli.ba.params import BAParams
from droidw_cli.config import FrontendConfig, TrackConfig
from droidw_cli.correspondence.base import Correspondence, MatchCall
from droidw_cli.dynamics.epipolar import MAX_MOVING, epipolar_distance, moving_mask
from droidw_cli.dynamics.inloop import KeyframeMasks, observed_disparity
from droidw_cli.geometry.poses import compose, extrapolate, interpolate
from droidw_cli.slam import graph
from droidw_cli.slam.depth_prior import seed_disparity
from droidw_cli.slam.distance import candidate_distance, frame_distance, transfer_disparity
from droidw_cli.slam.evidence import EVIDENCE_CHANNELS
from droidw_cli.slam.keyframe_maps import KeyframeMaps
from droidw_cli.slam.focal import clamp_focal, focal_observable
from droidw_cli.slam.keyframes import KeyframeBuffer
from droidw_cli.slam.optimizer import SharedState, run_window, window_state
from droidw_cli.slam.parallax import homography_parallax
from droidw_cli.slam.placement import place_keyframe
from droidw_cli.slam.starts import AdjacentStart, induced_start
from droidw_cli.slam.two_view import two_view

#: the two-view model of initialisation spans keyframes 0 … TWO_VIEW_SPAN (slam/two_view.py)
TWO_VIEW_SPAN = 2
#: proximity edges are sought for the keyframes this close to the newest (DROID: t1 − 5)
PROXIMITY_RECENT = 5


def window_reach(f: FrontendConfig, horizon: int) -> int:
    """The most keyframes a window holds: ``window``, or with ``window_span`` up to ``window_max``
    (:meth:`Frontend._window_start`), inside the backend's ``horizon``."""
    return max(f.window, min(f.window_max, horizon) if f.window_span else 0)


def _epipolar_of(c: Correspondence) -> np.ndarray | None:
    """The epipolar distance map of a correspondence (:func:`droidw_cli.dynamics.epipolar.epipolar_distance`)."""
    return epipolar_distance(c.flow, c.weight[..., 0].numpy())


class Frontend(KeyframeMaps):
    """Owns the keyframe buffer, the edge cache and the window BA."""

    def __init__(self, cfg: TrackConfig, params: BAParams, backend: BABackend, correspondence,
                 grid: tuple[int, int], intrinsics8: torch.Tensor, feature_channels: int):
        self.cfg = cfg
        self.fcfg = cfg.frontend
        self.reach = window_reach(cfg.frontend, cfg.backend.horizon)
        self.params = params
        self.backend = backend
        self.correspondence = correspondence
        dev = backend.device
        self.buffer = KeyframeBuffer(grid, feature_channels, torch.float16 if cfg.features.half else torch.float32,
                                     device=dev)
        self.cache = graph.EdgeCache(device=dev)
        extra = EVIDENCE_CHANNELS if params.uncertainty.evidence else 0
        theta = torch.zeros(feature_channels + extra + 1, device=dev) if feature_channels else None
        self.shared = SharedState(intrinsics8.clone().float().to(dev), theta)
        # --calib auto: the focal guess, and the BA settings for windows that cannot constrain f
        self._focal0 = float(intrinsics8[0])
        self._fixed_focal = dataclasses.replace(params, optimize_focal="none")
        self.focal_estimated = False  # some window BA had the focal length free (it saw enough rotation)
        self.images: dict[int, np.ndarray] = {}
        self.initialised = False
        self.on_remove = None  # called with a keyframe's index just before keyframe removal drops it
        # early matches of adjacent pairs made on another thread (slam/scout.py's Scout: matched(frame i,
        # frame j) → match_adjacent's result or None, hold() while this frontend matches, release() after)
        self.early = None
        self.starts = None  # the motion filter's flows between candidates (the scout's start(frame, previous))
        self._adjacent = AdjacentStart(intrinsics8, cfg.frontend.rotation_start)  # their starts (slam/starts.py)
        # epipolar motion segmentation: (Sampson distance map, raw confidence) of the window's edges.  Not while the
        # focal length is estimated: on lady-running with --calib auto the masks flagged 27-41 % of the view (not
        # only the runner) and the estimated fx fell from 617 px to 17 px.
        self._segmenting = (cfg.dynamics.epipolar and params.uncertainty.enable and feature_channels > 0
                            and params.optimize_focal == "none")
        self._epipolar: dict[tuple[int, int], tuple[np.ndarray, torch.Tensor]] = {}
        # dynamic masks of every keyframe (scene consistency with dynamics.mode consistency|both)
        # monocular without scene consistency: the output masks come from the short edges' flow (dynamics/posthoc.py)
        keep_flow = cfg.dynamics.mode != "none" and not cfg.dynamics.consistency and not cfg.io.use_depth
        self.masks = KeyframeMasks(cfg.dynamics, grid, cfg.dynamics.consistency, keep_flow=keep_flow)
        self._raw: dict[tuple[int, int], torch.Tensor] = {}  # raw confidences, while masks may change
        self._masking = self._segmenting or cfg.dynamics.consistency
        h, w = grid
        ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
        self.grid_coords = torch.stack([xs, ys], -1)  # on the host, with the flow

    # ------------------------------------------------------------------ helpers
    def _induced_flow(self, pairs: list[tuple[int, int]]) -> tuple[torch.Tensor, torch.Tensor]:
        """Grid-pixel flow (E, h, w, 2) induced by the current poses/depths, and validity (on the host)."""
        ii = torch.tensor([p[0] for p in pairs], device=self.buffer.device)
        jj = torch.tensor([p[1] for p in pairs], device=self.buffer.device)
        lo, hi = min(min(p) for p in pairs), max(max(p) for p in pairs) + 1
        state = window_state(self.buffer, lo, hi, self.shared, with_features=False)
        coords, valid = self.backend.reproject(state, ii - lo, jj - lo, self.params.min_depth)
        return coords.cpu() - self.grid_coords, valid.cpu()

    def match(self, pairs: list[tuple[int, int]], images: dict[int, np.ndarray]) -> None:
        """Cache targets for these pairs (not cached yet) from the given keyframe images (the backend's
        proximity edges, whose images left the window), started as :meth:`_match` says."""
        self._match(pairs, use_prior=True, images=images)

    def _match(self, pairs: list[tuple[int, int]], use_prior: bool, images: dict[int, np.ndarray] | None = None) -> None:
        """Compute and cache targets for the pairs not cached yet, each flow started as :mod:`droidw_cli.slam.starts`
        says (``use_prior`` False: from the motion filter's flow only).  Both directions of a pair come from one
        forward-backward call; an adjacent pair the scout matched early is taken from it."""
        images = self.images if images is None else images
        todo = [p for p in pairs if p not in self.cache]
        if not todo:
            return
        size = images[todo[0][0]].shape[:2]
        init: list[np.ndarray | None] = [None] * len(todo)  # adjacent pairs' starts: made below, for the calls only
        if use_prior:  # wider pairs from the map; adjacent ones as the scout matches them (the same bytes)
            prior = [n for n, (i, j) in enumerate(todo) if abs(i - j) > 1]
            if prior:
                flow, valid = self._induced_flow([todo[n] for n in prior])
                for m, n in enumerate(prior):
                    init[n] = induced_start(flow[m], valid[m], size)
        first = dict(zip(todo, init))
        done: set[tuple[int, int]] = set()
        calls, keys = [], []
        for (i, j), f0 in first.items():
            if (i, j) in done:
                continue
            both = (j, i) in first and (j, i) not in done  # both directions from one forward-backward pair
            early = self._matched_early(i, j) if both and abs(i - j) == 1 else None
            if early is not None:
                for key, (c, epipolar) in zip([(i, j), (j, i)], early):
                    self._store(key, c, epipolar)
                done.update([(i, j), (j, i)])
                continue
            if abs(i - j) == 1:
                f0 = self._adjacent_start(i, j, size)
            calls.append(MatchCall(images[i], images[j], f0, both))
            keys.append([(i, j), (j, i)] if both else [(i, j)])
            done.update(keys[-1])
        derive = _epipolar_of if self._segmenting else None  # on the flow's thread too
        if self.early is not None:
            self.early.hold()  # both cores match here: no early match beside them
        try:
            matched = self.correspondence.match_all(calls, derive) if calls else []
        finally:
            if self.early is not None:
                self.early.release()  # the BA that follows leaves a core to them
        for ks, results in zip(keys, matched):
            for key, (c, epipolar) in zip(ks, results):
                self._store(key, c, epipolar)
        if self._masking:
            self._mask_movers({i for i, _ in todo})

    def match_adjacent(self, image_i: np.ndarray, image_j: np.ndarray, start: np.ndarray | None = None,
                       source=None) -> list[tuple[Correspondence, object]]:
        """The pair (i, j), (j, i) as :meth:`_match` makes it from the motion filter's flow j → i (``start``, half
        size; :func:`~droidw_cli.slam.starts.adjacent_start`), with the epipolar maps when segmenting, every job on the calling thread,
        so that another thread may ask for it (:mod:`droidw_cli.slam.scout`); ``source``: the correspondence
        source to use (default: the frontend's)."""
        derive = _epipolar_of if self._segmenting else None
        source = self.correspondence if source is None else source
        init = None if start is None else self._adjacent(start, image_i.shape[:2], invert=True)
        return source.match_all([MatchCall(image_i, image_j, init, True)], derive, serial=True)[0]

    def _adjacent_start(self, i: int, j: int, size: tuple[int, int]) -> np.ndarray | None:
        """The start of pair (i, j) from the motion filter's flow between the two, when one was the other's
        reference (``self.starts``, the scout); None otherwise."""
        if self.starts is None:
            return None
        fi, fj = self.buffer.frame_index[i], self.buffer.frame_index[j]
        later = self.starts.start(fi, fj)  # j → i
        if later is not None:
            return self._adjacent(later, size, invert=True)
        earlier = self.starts.start(fj, fi)  # i → j
        return None if earlier is None else self._adjacent(earlier, size, invert=False)

    def _matched_early(self, i: int, j: int) -> list[tuple[Correspondence, object]] | None:
        """The pair (i, j), (j, i) as :meth:`match_adjacent` made it on another thread (``self.early``),
        when it did."""
        if self.early is None:
            return None
        return self.early.matched(self.buffer.frame_index[i], self.buffer.frame_index[j])

    def _store(self, key: tuple[int, int], c, epipolar: np.ndarray | None) -> None:
        self.cache.put(*key, c.target, c.weight, born=self.shared.iterations)
        self.masks.keep_edge(*key, c.target, c.weight)
        if self._masking:
            self._raw[key] = c.weight
        if self._segmenting and epipolar is not None:
            self._epipolar[key] = (epipolar, c.weight)

    def _mask_movers(self, frames: set[int]) -> None:
        """Zero the confidence of the masked pixels of these keyframes' outgoing edges.
        Keyframe i's mask: its scene-consistency mask (``dynamics.mode`` consistency|both) joined with its epipolar
        mask (epipolar|both; from all its edges so far, grown less where it would cover over ``MAX_MOVING``, left
        out where it does ungrown), applied to the raw confidences.  ``epipolar_in_view`` (once initialised): a cell
        neither map nor flow keeps in an edge's view (:meth:`in_view`) is no evidence there, and gets no weight."""
        d = self.cfg.dynamics
        for i in frames:
            mine = [(key, w) for key, w in self._raw.items()
                    if key[0] == i and (d.consistency or key in self._epipolar)]
            if not mine:
                continue
            masked = self.masks.current[i].numpy().copy()
            keys, sees = [key for key, _ in mine if key in self._epipolar], {}
            if self._segmenting and keys:
                seen = self.in_view(i, [j for _, j in keys], [self.cache.target(k) for k in keys]) \
                    if self.initialised and d.epipolar_in_view else None
                sees = dict(zip(keys, seen or []))
                moving = moving_mask([self._epipolar[key][0] for key in keys], d.epipolar_thresh, d.epipolar_dilate,
                                     MAX_MOVING, seen)
                if moving.mean() > MAX_MOVING:
                    moving[:] = False
                self.masks.record(i, moving)
                masked |= moving
            keep = torch.from_numpy(~masked).float()[..., None]
            for (a, b), w in mine:
                k = keep * torch.from_numpy(sees[a, b])[..., None] if (a, b) in sees else keep
                self.cache.put(a, b, self.cache.target((a, b)), w * k)

    def _detect(self, frames: list[int]) -> None:
        """Scene-consistency masks of these keyframes under the current poses and depths, applied to BA."""
        if not self.cfg.dynamics.consistency:
            return
        buf = self.buffer
        n = len(buf)
        disps = observed_disparity(buf.disps[:n], buf.depth_prior[:n] if buf.has_prior else None)
        for k in frames:
            objects = self.masks.detect(k, buf.poses[:n], disps, self.shared.intrinsics, self.masks.sources(k, n))
            self.masks.set_current(k, None if objects is None else objects.mask)
        self._mask_movers(set(frames))

    def _optimise(self, lo: int, hi: int, pairs: list[tuple[int, int]], iters: int, focal: bool = True) -> float:
        """Window BA over keyframes [lo, hi); the focal length moves only when ``focal`` and the
        window constrains it (:func:`droidw_cli.slam.focal.focal_observable`), and stays in its bounds."""
        edges = self.cache.edge_set(pairs, offset=lo)
        fixed = 1 if lo == 0 else min(2, hi - lo - 1)
        params = self.params
        if params.optimize_focal != "none" and not (focal and focal_observable(self.buffer.poses[lo:hi], self.cfg.calib)):
            params = self._fixed_focal
        self.focal_estimated |= params.optimize_focal != "none"
        cost = run_window(self.backend, self.buffer, lo, hi, edges, params, self.shared, iters, fixed,
                          robust_sigma=self.fcfg.robust_sigma)
        if params.optimize_focal != "none":
            self.shared.intrinsics = clamp_focal(self.shared.intrinsics, self._focal0, self.cfg.calib)
        return cost

    def distance(self, ii: list[int], jj: list[int], stride: int = 1) -> torch.Tensor:
        """Frame distances d(i, j) in grid px under the current poses and disparities (every
        ``stride``-th grid pixel, :func:`~droidw_cli.slam.distance.frame_distance`)."""
        buf = self.buffer
        return frame_distance(buf.poses[:len(buf)], buf.disps[:len(buf)], self.shared.intrinsics,
                              torch.tensor(ii, dtype=torch.long, device=buf.device),
                              torch.tensor(jj, dtype=torch.long, device=buf.device),
                              self.fcfg.beta, self.params.min_depth, stride=stride)

    # ------------------------------------------------------------------ public
    def doomed(self, frame_index: int, full: float) -> bool:
        """Would keyframe removal drop candidate ``frame_index`` at once (``frontend.skip_doomed``)?  Yes when
        its predicted distance to the newest keyframe (:func:`~droidw_cli.slam.distance.candidate_distance`;
        ``full``: the motion filter's flow since that keyframe) is under ``keyframe_thresh`` and the gap so far
        is at most half of ``removal_max_span`` (the next candidate is expected as far on)."""
        f, buf = self.fcfg, self.buffer
        k = len(buf)
        if not (f.skip_doomed and self.initialised and k >= 2):
            return False
        f1, f0 = buf.frame_index[k - 1], buf.frame_index[k - 2]
        if 2 * (frame_index - f1) > f.removal_max_span:
            return False
        d = candidate_distance(buf.poses[k - 2], buf.poses[k - 1], buf.disps[k - 1], self.shared.intrinsics,
                               (frame_index - f1) / max(1, f1 - f0), full, f.beta, self.params.min_depth,
                               f.proximity_stride)
        return d < f.keyframe_thresh

    def add_keyframe(self, frame_index: int, timestamp: float, image: np.ndarray, thumbnail: np.ndarray,
                     features: torch.Tensor | None, depth_prior: torch.Tensor | None) -> int:
        """Insert a keyframe and run initialisation or the window update; returns its index."""
        buf = self.buffer
        k = len(buf)
        if self.initialised and k >= 2:
            pose = extrapolate(buf.poses[k - 2], buf.poses[k - 1], self.fcfg.velocity_damping)
            disp = transfer_disparity(buf.poses[k - 1], buf.disps[k - 1], pose, self.shared.intrinsics,
                                      self.params.min_depth)
        else:
            pose, disp = torch.tensor([0, 0, 0, 0, 0, 0, 1.0]), 1.0
        disp = seed_disparity(disp, depth_prior, buf.disps.shape[1:], buf.device)
        buf.append(frame_index, timestamp, pose, disp, thumbnail, features, depth_prior)
        self.images[k] = image
        self.masks.append(image, timestamp)
        if not self.initialised:
            if self._ready(k):
                self._initialise()
        else:
            k = self._update(k)
        self._evict(k)
        return k

    def _ready(self, k: int) -> bool:
        """Enough keyframes, and (below ``warmup``) enough parallax, to initialise."""
        f = self.fcfg
        n = k + 1
        if n >= f.warmup:
            return True
        return n >= max(2, f.warmup_min) and homography_parallax(self.images[0], self.images[k]) >= f.init_parallax

    def _initialise(self) -> None:
        buf, f = self.buffer, self.fcfg
        n = len(buf)
        init_radius = max(3, f.radius)
        self.shared.iterations = 0  # the uncertainty warm-up (official: 8 unweighted iterations) counts from here
        start = self._two_view_start(init_radius)
        for m in range(start, n + 1):
            if m >= 3:
                buf.poses[m - 1] = extrapolate(buf.poses[m - 3], buf.poses[m - 2], 1.0)
                prior = buf.depth_prior[m - 1] if buf.has_prior else None
                moved = transfer_disparity(buf.poses[m - 2], buf.disps[m - 2], buf.poses[m - 1],
                                           self.shared.intrinsics, self.params.min_depth)
                buf.disps[m - 1] = seed_disparity(moved, prior, buf.disps.shape[1:], buf.device)
            pairs = graph.init_pairs(m, init_radius)
            self._match(pairs, use_prior=m >= 3)
            self._optimise(0, m, pairs, 4 if m < n else f.init_iters, focal=False)
        self._optimise(0, n, graph.init_pairs(n, init_radius), f.iters1 + f.iters2, focal=False)
        self._detect(list(range(n)))
        self.initialised = True

    def _two_view_start(self, radius: int) -> int:
        """Start the first ``TWO_VIEW_SPAN`` + 1 keyframes from a two-view model (:mod:`droidw_cli.slam.two_view`)
        and optimise them; returns the keyframe count the incremental initialisation goes on from (2, the flat
        start, where the pair does not determine a model, or in RGB-D mode, whose sensor depth does)."""
        buf = self.buffer
        m = min(len(buf) - 1, TWO_VIEW_SPAN)
        if buf.has_prior or m < 1:
            return 2
        derive = _epipolar_of if self._segmenting else None
        matched = self.correspondence.match_all([MatchCall(self.images[0], self.images[m], None, True)], derive)[0]
        model = two_view(matched[0][0].target, matched[0][0].weight, self.shared.intrinsics)
        if model is None:  # nothing cached: the flat start goes on as if this was not tried
            return 2
        for key, (c, epipolar) in zip([(0, m), (m, 0)], matched):
            self._store(key, c, epipolar)
        pairs = graph.init_pairs(m + 1, radius)
        self._match(pairs, use_prior=False)
        frames = torch.tensor(buf.frame_index[:m + 1], dtype=torch.float32)
        alpha = (frames - frames[0]) / (frames[m] - frames[0])
        first = buf.poses[0].clone()
        end = compose(model.pose.to(first), first)
        buf.poses[:m + 1] = interpolate(first.expand(m + 1, 7), end.expand(m + 1, 7), alpha.to(first))
        buf.disps[0] = model.disparity.to(buf.disps)
        for k in range(1, m + 1):
            buf.disps[k] = transfer_disparity(buf.poses[0], buf.disps[0], buf.poses[k], self.shared.intrinsics,
                                              self.params.min_depth)
        self._optimise(0, m + 1, pairs, 4 if m + 1 < len(buf) else self.fcfg.init_iters, focal=False)
        return m + 2

    def _proximity(self, k: int, lo: int) -> list[tuple[int, int]]:
        """Proximity pairs of the newest keyframes within the window (DROID's frontend rule): at most
        ``proximity_max``, or one when keyframe k came under ``proximity_gap`` frames after its predecessor.
        Under fast motion keyframes come every few frames, and their neighbours' pairs already tie that
        stretch of the path to the window (docs/benchmarks.md, "One proximity pair under fast motion")."""
        f = self.fcfg
        cand = [(i, j) for i in range(max(lo, k - PROXIMITY_RECENT + 1), k + 1)
                for j in range(lo, i - f.radius) if (i, j) not in self.cache]
        if not cand:
            return []
        dist = self.distance([i for i, _ in cand], [j for _, j in cand], f.proximity_stride)
        existing = {p for p in self.cache.pairs() if min(p) >= lo}
        gap = self.buffer.frame_index[k] - self.buffer.frame_index[k - 1] if k >= 1 else f.proximity_gap
        limit = f.proximity_max if gap >= f.proximity_gap else min(1, f.proximity_max)
        return graph.select_proximity(cand, dist, f.flow_thresh, f.nms, existing, limit)

    def _update(self, k: int) -> int:
        """Window BA for the new keyframe k; returns its index after a possible removal."""
        f = self.fcfg
        lo = self._window_start(k)
        place_keyframe(self, k, f.place_iters)
        pairs = graph.radius_pairs(k, lo, f.radius) + self._proximity(k, lo)
        self._match(pairs, use_prior=True)
        self._window_ba(lo, k, f.iters1)
        span = self.buffer.frame_index[k] - self.buffer.frame_index[k - 2] if k >= 2 else 0
        if k - 1 >= 1 and span <= f.removal_max_span and float(self.distance([k - 2], [k - 1])[0]) < f.keyframe_thresh:
            if self.on_remove is not None:
                self.on_remove(k - 1)
            self._remove(k - 1)
            self._detect([k - 1])
            return k - 1
        self._detect([k])
        self._window_ba(lo, k, f.iters2)
        return k

    def _window_start(self, k: int) -> int:
        """The window's first keyframe: of the newest ``window`` keyframes, widened by older ones (to at
        most ``window_max``) until it reaches ``window_span`` input frames back.  Under fast rotation
        keyframes come every few frames, and 25 of them span too short a path to hold the scale."""
        f, frames = self.fcfg, self.buffer.frame_index
        lo = max(0, k - f.window + 1)
        while lo > 0 and k - lo + 1 < self.reach and frames[k] - frames[lo] < f.window_span:
            lo -= 1
        return lo

    def _window_ba(self, lo: int, k: int, iters: int) -> None:
        """BA over the window's young edges, its gauge (pose and scale) held by the two oldest keyframes the edges
        still reach: edges retire after ``max_age`` iterations, and on the ``drive`` preset the window's first
        keyframes were 15-20 older than any edge, so pose and scale were free (held by the damping alone)."""
        f = self.fcfg
        window = self.cache.young_pairs(self.shared.iterations, f.max_age, lo)
        window = graph.cap_edges(window, f.max_edges)
        reached = min(min(p) for p in window) if window else lo
        self._optimise(max(lo, reached), k + 1, window, iters)

    def _remove(self, k: int) -> None:
        """Keyframe removal: drop keyframe k with its edges and renumber the later ones."""
        self.buffer.remove(k)
        self.cache.remove_frame(k)
        self.masks.remove(k)

        def renumber(i: int) -> int:
            return i - (i > k)

        self.images = {renumber(i): v for i, v in self.images.items() if i != k}
        self._epipolar = {(renumber(a), renumber(b)): v for (a, b), v in self._epipolar.items() if k not in (a, b)}
        self._raw = {(renumber(a), renumber(b)): v for (a, b), v in self._raw.items() if k not in (a, b)}

    def drop_before(self, lo: int) -> None:
        """Forget every edge (targets, raw confidences, epipolar maps) with an end before keyframe lo."""
        self.cache.drop_before(lo)
        self._raw = {p: v for p, v in self._raw.items() if min(p) >= lo}
        self._epipolar = {p: v for p, v in self._epipolar.items() if min(p) >= lo}

    def archive(self, lo: int, hi: int) -> None:
        """Keyframes [lo, hi) leave the optimisation for good: freeze their u and confidence, drop features."""
        u = self.uncertainty(lo, hi)
        conf = self.confidence(lo, hi)
        for k in range(lo, hi):
            self.buffer.archive(k, None if u is None else u[k - lo], conf[k - lo])
        n = len(self.buffer)
        prior = self.buffer.depth_prior[:n] if self.buffer.has_prior else None
        self.masks.finalise(hi, self.buffer.poses[:n], observed_disparity(self.buffer.disps[:n], prior),
                            self.shared.intrinsics)

    def _evict(self, k: int) -> None:
        """Drop the working-resolution images and epipolar maps of keyframes that left the window."""
        for old in [i for i in self.images if i <= k - self.reach]:
            del self.images[old]
        for key in [key for key in self._epipolar if key[0] <= k - self.reach]:
            del self._epipolar[key]
        for key in [key for key in self._raw if key[0] <= k - self.reach]:
            del self._raw[key]
