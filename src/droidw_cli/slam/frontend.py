"""The frontend: initialisation and sliding-window local BA (DROID-SLAM skeleton).

* Initialisation on the first ``warmup`` keyframes: they are brought in one at
  a time (constant-velocity pose guess, constant disparity) with a few BA
  iterations each, then ``init_iters`` iterations over all of them.
* Update for each later keyframe k: edges to its ``radius`` predecessors plus
  proximity edges inside the window whose induced flow is under
  ``flow_thresh``; at most ``max_edges`` edges; ``iters1 + iters2``
  iterations over the window [k − window + 1, k].  The oldest two keyframes
  of a window that does not start at 0 stay fixed (gauge and scale).
* With the uncertainty on (and ``dynamics.epipolar``), every edge loses the
  pixels of its keyframe that the dominant epipolar geometry cannot explain
  (:mod:`droidw_cli.dynamics.epipolar`).  The learned uncertainty reads the
  map, so it cannot find movers that the map was built on: during
  initialisation, or when a mover walks in.  Ground-truth masks during
  initialisation only, with the uncertainty afterwards, took one synthetic
  sequence from 23 cm to 0.8 cm ATE; the epipolar masks are the same idea
  without ground truth.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from droidw_cli.ba.interface import BABackend
from droidw_cli.ba.params import BAParams
from droidw_cli.config import TrackConfig
from droidw_cli.dynamics.epipolar import MAX_MOVING, epipolar_distance, moving_mask
from droidw_cli.slam import graph
from droidw_cli.slam.evidence import EVIDENCE_CHANNELS, evidence_maps
from droidw_cli.slam.keyframes import KeyframeBuffer
from droidw_cli.slam.optimizer import SharedState, run_window, window_state
from droidw_cli.slam.poses import extrapolate


class Frontend:
    """Owns the keyframe buffer, the edge cache and the window BA."""

    def __init__(self, cfg: TrackConfig, params: BAParams, backend: BABackend, correspondence,
                 grid: tuple[int, int], intrinsics8: torch.Tensor, feature_channels: int):
        self.cfg = cfg
        self.fcfg = cfg.frontend
        self.params = params
        self.backend = backend
        self.correspondence = correspondence
        self.buffer = KeyframeBuffer(grid, feature_channels, torch.float16 if cfg.features.half else torch.float32)
        self.cache = graph.EdgeCache()
        extra = EVIDENCE_CHANNELS if params.uncertainty.evidence else 0
        theta = torch.zeros(feature_channels + extra + 1) if feature_channels else None
        self.shared = SharedState(intrinsics8.clone().float(), theta)
        self.images: dict[int, np.ndarray] = {}
        self.initialised = False
        # epipolar motion segmentation: (Sampson distance map, raw confidence) of the window's edges.
        # Not while the focal length is estimated: on lady-running with --calib auto the masks
        # flagged 27-41 % of the view (not only the runner) and the estimated fx fell from
        # 617 px to 17 px.
        self._segmenting = (cfg.dynamics.epipolar and params.uncertainty.enable and feature_channels > 0
                            and params.optimize_focal == "none")
        self._epipolar: dict[tuple[int, int], tuple[np.ndarray, torch.Tensor]] = {}
        h, w = grid
        ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
        self._grid = torch.stack([xs, ys], -1)

    # ------------------------------------------------------------------ helpers
    def _induced_flow(self, pairs: list[tuple[int, int]]) -> tuple[torch.Tensor, torch.Tensor]:
        """Grid-pixel flow (E, h, w, 2) induced by the current poses/depths, and validity."""
        ii = torch.tensor([p[0] for p in pairs])
        jj = torch.tensor([p[1] for p in pairs])
        lo = int(min(ii.min(), jj.min()))
        hi = int(max(ii.max(), jj.max())) + 1
        state = window_state(self.buffer, lo, hi, self.shared, with_features=False)
        coords, valid = self.backend.reproject(state, ii - lo, jj - lo, self.params.min_depth)
        return coords - self._grid, valid

    def _full_res_flow(self, flow_grid: torch.Tensor, valid: torch.Tensor, size: tuple[int, int]) -> np.ndarray:
        f = torch.where(valid[..., None], flow_grid, torch.zeros_like(flow_grid)).numpy() * 8.0
        return cv2.resize(np.ascontiguousarray(f), (size[1], size[0]), interpolation=cv2.INTER_LINEAR)

    def _match(self, pairs: list[tuple[int, int]], use_prior: bool) -> None:
        """Compute and cache targets for the pairs not cached yet."""
        todo = [p for p in pairs if p not in self.cache]
        if not todo:
            return
        init = [None] * len(todo)
        if use_prior:
            wide = [n for n, (i, j) in enumerate(todo) if abs(i - j) > 1]
            if wide:
                flow, valid = self._induced_flow([todo[n] for n in wide])
                size = self.images[todo[wide[0]][0]].shape[:2]
                for m, n in enumerate(wide):
                    init[n] = self._full_res_flow(flow[m], valid[m], size)
        for (i, j), f0 in zip(todo, init):
            c = self.correspondence.match(self.images[i], self.images[j], init_flow=f0)
            self.cache.put(i, j, c.target, c.weight)
            if self._segmenting:
                d = epipolar_distance(c.flow, c.weight[..., 0].numpy())
                if d is not None:
                    self._epipolar[(i, j)] = (d, c.weight)
        if self._segmenting:
            self._mask_movers({i for i, _ in todo})

    def _mask_movers(self, frames: set[int]) -> None:
        """Zero the confidence of the epipolar movers of these keyframes' outgoing edges.

        The mask of keyframe i is recomputed from all its edges so far, always
        applied to the raw confidences.  A mask over ``MAX_MOVING`` of the view
        means no dominant rigid motion was found; that keyframe is left alone.
        """
        d = self.cfg.dynamics
        for i in frames:
            mine = [(key, w) for key, (_, w) in self._epipolar.items() if key[0] == i]
            if not mine:
                continue
            moving = moving_mask([self._epipolar[key][0] for key, _ in mine], d.epipolar_thresh, d.epipolar_dilate)
            if moving.mean() > MAX_MOVING:
                moving[:] = False
            keep = torch.from_numpy(~moving).float()[..., None]
            for (a, b), w in mine:
                self.cache.put(a, b, self.cache.targets[(a, b)][0], w * keep)

    def _optimise(self, lo: int, hi: int, pairs: list[tuple[int, int]], iters: int) -> float:
        edges = self.cache.edge_set(pairs, offset=lo)
        fixed = 1 if lo == 0 else min(2, hi - lo - 1)
        return run_window(self.backend, self.buffer, lo, hi, edges, self.params, self.shared, iters, fixed)

    # ------------------------------------------------------------------ public
    def add_keyframe(self, frame_index: int, timestamp: float, image: np.ndarray, thumbnail: np.ndarray,
                     features: torch.Tensor | None, depth_prior: torch.Tensor | None) -> int:
        """Insert a keyframe and run initialisation or the window update."""
        buf = self.buffer
        k = len(buf)
        if self.initialised and k >= 2:
            pose = extrapolate(buf.poses[k - 2], buf.poses[k - 1], self.fcfg.velocity_damping)
            disp = float(buf.disps[k - 1].median())
        else:
            pose, disp = torch.tensor([0, 0, 0, 0, 0, 0, 1.0]), 1.0
        buf.append(frame_index, timestamp, pose, disp, thumbnail, features, depth_prior)
        self.images[k] = image
        if not self.initialised:
            if len(buf) >= self.fcfg.warmup:
                self._initialise()
        else:
            self._update(k)
        self._evict(k)
        return k

    def _initialise(self) -> None:
        buf, f = self.buffer, self.fcfg
        n = len(buf)
        init_radius = max(3, f.radius)
        self.shared.iterations = 0  # the uncertainty warm-up (official: 8 unweighted iterations) counts from here
        for m in range(2, n + 1):
            if m >= 3:
                buf.poses[m - 1] = extrapolate(buf.poses[m - 3], buf.poses[m - 2], 1.0)
                buf.disps[m - 1] = buf.disps[m - 2].median()
            pairs = graph.init_pairs(m, init_radius)
            self._match(pairs, use_prior=m >= 3)
            self._optimise(0, m, pairs, 4 if m < n else f.init_iters)
        self._optimise(0, n, graph.init_pairs(n, init_radius), f.iters1 + f.iters2)
        self.initialised = True

    def _update(self, k: int) -> None:
        f = self.fcfg
        lo = max(0, k - f.window + 1)
        pairs = graph.radius_pairs(k, lo, f.radius)
        candidates = list(range(lo, k - f.radius))
        if candidates:
            flow, valid = self._induced_flow([(k, c) for c in candidates])
            mag = (flow.norm(dim=-1) * valid).sum((1, 2)) / valid.sum((1, 2)).clamp(min=1)
            mag = torch.where(valid.float().mean((1, 2)) > 0.5, mag * 8.0, torch.full_like(mag, float("inf")))
            pairs += graph.select_proximity(k, candidates, mag, f.flow_thresh, limit=3)
        self._match(pairs, use_prior=True)
        window = [p for p in self.cache.pairs() if min(p) >= lo]
        window = graph.cap_edges(window, f.max_edges)
        self._optimise(lo, k + 1, window, f.iters1 + f.iters2)

    def evidence(self) -> torch.Tensor | None:
        """Evidence channels of every keyframe from all cached edges (None when unused)."""
        unc = self.params.uncertainty
        n = len(self.buffer)
        if not (unc.enable and unc.evidence) or self.buffer.features is None:
            return None
        if n < 2 or len(self.cache) == 0:
            return torch.zeros(n, EVIDENCE_CHANNELS, *self.buffer.grid)
        state = window_state(self.buffer, 0, n, self.shared, with_features=False)
        return evidence_maps(self.backend, state, self.cache.edge_set(self.cache.pairs()), self.params.min_depth)

    def _evict(self, k: int) -> None:
        """Drop the working-resolution images and epipolar maps of keyframes that left the window."""
        for old in [i for i in self.images if i <= k - self.fcfg.window]:
            del self.images[old]
        for key in [key for key in self._epipolar if key[0] <= k - self.fcfg.window]:
            del self._epipolar[key]
