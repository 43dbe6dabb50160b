"""The backend: global BA with proximity (loop) edges over the keyframe graph, bounded.

DROID-SLAM's backend adds, over the whole keyframe graph, the pairs (i, j)
with |i − j| > ``radius`` whose frame distance d(i, j) (:mod:`droidw_cli.slam.distance`)
is under ``thresh`` = 25 grid px, closest first, with non-maximum suppression
over ``nms`` = 5 keyframes against every edge already in the graph (so the
frontend's own radius and proximity edges suppress their neighbourhood, and
what is left are revisits: loops).  Their correspondences start from the
flow that the current poses and depths induce.  Then a BA over all the edges,
θ frozen (DROID-W: "θ is frozen during the final global BA").

Bounded: the problem covers only the newest ``horizon`` keyframes, [lo, n).
Older keyframes keep their poses and leave the problem for good: their u
and confidence maps are frozen, and their features, edges and stored
images dropped (:meth:`~droidw_cli.slam.frontend.Frontend.archive`).  A long video therefore builds
a sequence of overlapping bounded problems, never one that grows with it:
every ``every`` new keyframes during tracking (``periodic_iters``
iterations), and once at the end (``iters``).

The images of the keyframes in the problem are kept JPEG-encoded at the
working resolution (``image_quality``), about a tenth of their raw size, and
each run hands the heap's free pages back before and after it and maps its large
temporaries on their own (:mod:`droidw_cli.runtime.heap`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import torch

from droidw_cli.config import BackendConfig
from droidw_cli.io.jpeg import decode_rgb, encode_rgb
from droidw_cli.runtime.heap import large_blocks_mapped, release_free_memory
from droidw_cli.runtime.threads import torch_threads_set
from droidw_cli.slam import graph
from droidw_cli.slam.distance import frame_distance
from droidw_cli.slam.frontend import Frontend
from droidw_cli.slam.optimizer import run_window

#: the candidates' frame distance is averaged over every DISTANCE_STRIDE-th grid pixel
DISTANCE_STRIDE = 4


class KeyframeImages:
    """Working-resolution keyframe images, JPEG-encoded, keyed by source frame index."""

    def __init__(self, quality: int):
        self.quality = int(quality)
        self._data: dict[int, np.ndarray] = {}

    def __len__(self) -> int:
        return len(self._data)

    @property
    def nbytes(self) -> int:
        return sum(v.nbytes for v in self._data.values())

    def put(self, frame_index: int, image: np.ndarray) -> None:
        self._data[int(frame_index)] = encode_rgb(image, self.quality)

    def get(self, frame_index: int) -> np.ndarray:
        return decode_rgb(self._data[int(frame_index)])

    def keep(self, frame_indices: set[int]) -> None:
        """Forget every image whose frame index is not in ``frame_indices``."""
        self._data = {k: v for k, v in self._data.items() if k in frame_indices}


class GlobalBackend:
    """Periodic and final bounded global BA with proximity edges (module docstring)."""

    def __init__(self, frontend: Frontend, cfg: BackendConfig, threads: int = 0):
        self.fe = frontend
        self.cfg = cfg
        self.threads = threads  # torch threads of its BA (0: as the caller has them); the frontend's workers idle then
        self.images = KeyframeImages(cfg.image_quality)
        self.searched = 0  # keyframes below this index have had their proximity candidates evaluated
        self.last_run = 0  # keyframe count at the last run
        self.lo = 0  # the problem's first keyframe; everything below is final
        self.loop_edges = 0

    @property
    def active(self) -> bool:
        return self.cfg.enable

    def keyframe_added(self, k: int, image: np.ndarray) -> None:
        """Keep keyframe k's working image; run the periodic BA when it is due."""
        if not self.active:
            return
        self.images.put(self.fe.buffer.frame_index[k], image)
        n = len(self.fe.buffer)
        if self.cfg.every > 0 and self.fe.initialised and n - self.last_run >= self.cfg.every:
            self.run(self.cfg.periodic_iters)

    def finish(self) -> float:
        """The final global BA; returns its cost (nan when there is nothing to optimise)."""
        if not self.active or self.cfg.iters <= 0:
            return float("nan")
        return self.run(self.cfg.iters)

    # ------------------------------------------------------------------ internals
    def _candidates(self, lo: int, n: int) -> list[tuple[int, int]]:
        """Unordered pairs (i, j), j < i − radius, with i not searched yet, inside [lo, n)."""
        start = max(lo, self.searched)
        return [(i, j) for i in range(start, n) for j in range(lo, i - self.cfg.radius)]

    def _proximity(self, lo: int, n: int) -> list[tuple[int, int]]:
        cand = [p for p in self._candidates(lo, n) if p not in self.fe.cache]
        self.searched = n
        if not cand:
            return []
        fe, buf = self.fe, self.fe.buffer
        ii = torch.tensor([p[0] for p in cand], dtype=torch.long, device=buf.device)
        jj = torch.tensor([p[1] for p in cand], dtype=torch.long, device=buf.device)
        dist = frame_distance(buf.poses[:n], buf.disps[:n], fe.shared.intrinsics, ii, jj, fe.fcfg.beta,
                              fe.params.min_depth, stride=DISTANCE_STRIDE)
        existing = {p for p in fe.cache.pairs() if min(p) >= lo}
        return graph.select_proximity(cand, dist, self.cfg.thresh, self.cfg.nms, existing, self.cfg.max_new)

    def run(self, iters: int) -> float:
        """One bounded global BA over [lo, n) with new proximity edges; returns the final cost."""
        with large_blocks_mapped():
            cost = self._run(iters)
        release_free_memory()  # the run's temporaries go back now, not at the next run (heap.py)
        return cost

    def _run(self, iters: int) -> float:
        fe = self.fe
        n = len(fe.buffer)
        self.last_run = n
        if not fe.initialised or n < 3:
            return float("nan")
        lo = max(0, n - self.cfg.horizon)
        if lo > self.lo:
            fe.archive(self.lo, lo)
            fe.drop_before(lo)
            self.lo = lo
        self.images.keep(set(fe.buffer.frame_index[lo:n]))
        release_free_memory()  # the run's temporaries start from what is live, not from old holes (heap.py)
        pairs = self._proximity(lo, n)
        if pairs:
            frames = {k for p in pairs for k in p}
            images = {k: fe.images[k] if k in fe.images else self.images.get(fe.buffer.frame_index[k]) for k in frames}
            fe.match(pairs, images)
            self.loop_edges += len(pairs)
        edges = fe.cache.edge_set(fe.cache.pairs(), offset=lo)
        params = fe.params
        if params.optimize_focal != "none":
            params = dataclasses.replace(params, optimize_focal="none")  # calibration is settled by now
        fixed = 1 if lo == 0 else 2
        with torch.no_grad(), torch_threads_set(self.threads or torch.get_num_threads()):
            return run_window(fe.backend, fe.buffer, lo, n, edges, params, fe.shared, iters, fixed=fixed,
                              optimize_theta=not params.uncertainty.freeze_in_global, robust_sigma=self.cfg.robust_sigma)
