"""Dynamic masks inside the tracker: scene consistency per new keyframe, the masks of every keyframe.

:class:`KeyframeMasks` lives beside the frontend's keyframe buffer (same
indices, renumbered on keyframe removal).  Per keyframe k it keeps the colour
on the 1/8 grid and M_k, the union of every dynamic mask its pixels were ever
given (scene consistency, epipolar), which is what BA zeroes and what the
static map leaves out.  The masks are kept bit-packed (:class:`PackedMasks`);
with the grid colour (9 KB at 48 × 64) about 10 KB a keyframe.

Scene consistency for a new keyframe k (ADD-SLAM, with the map's render
replaced by the reprojection of earlier keyframes), with S = the
``consistency_sources`` keyframes before k:

    Î_s, D̂_s = predict_views(k ← s)                        (warp.py)
    M_ic^d   = inconsistency(I_k, D_k, Î, D̂; τ = k_τ · median)  (consistency.py, k_τ = tau_scale = 20)
    objects  = segmenter.segment(M_ic^d, I_k, D_k)          (segmenter.py; built-in: region growing)

D is the sensor depth where the run has one (RGB-D: metric, zero = unknown,
so those pixels are never flagged) and the current BA depth 1/d otherwise.
Poses are the current window estimates.  A mask covering more than
``MAX_MASKED`` of the view means the prediction itself failed (a poor pose
early on); such a mask is dropped, as the epipolar masks are.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import Tensor

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics.consistency import inconsistency
from droidw_cli.dynamics.params import DetectionParams
from droidw_cli.dynamics.posthoc import motion_masks
from droidw_cli.dynamics.refine import Objects
from droidw_cli.dynamics.segmenter import get_segmenter
from droidw_cli.dynamics.warp import predict_views

#: a consistency mask over this share of the view is taken for a failed prediction and dropped
MAX_MASKED = 0.5
#: the grid flow of edges i → j with |i − j| up to this is kept for the final masks
EDGE_SPAN = 2


class PackedMasks:
    """A list of (h, w) bool masks kept bit-packed (384 bytes at 48 × 64 instead of 3 KB plus a tensor's overhead).

    Reading ``masks[k]`` unpacks a fresh bool tensor; ``masks[k] = mask`` packs
    one, so ``masks[k] |= other`` works as for a list of tensors.  A long video
    keeps two of these per keyframe (the union and the current consistency mask).
    """

    def __init__(self, grid: tuple[int, int]):
        self.grid = grid
        self._bits: list[np.ndarray] = []

    def __len__(self) -> int:
        return len(self._bits)

    def _pack(self, mask: Tensor | np.ndarray) -> np.ndarray:
        m = mask.detach().cpu().numpy() if isinstance(mask, Tensor) else np.asarray(mask)
        if m.shape != self.grid:
            raise ValueError(f"mask of shape {m.shape}, expected {self.grid}")
        return np.packbits(m.astype(bool, copy=False).reshape(-1))

    def _unpack(self, bits: np.ndarray) -> np.ndarray:
        return np.unpackbits(bits, count=self.grid[0] * self.grid[1]).view(bool).reshape(self.grid)

    def append(self, mask: Tensor | np.ndarray) -> None:
        self._bits.append(self._pack(mask))

    def __getitem__(self, k: int) -> Tensor:
        return torch.from_numpy(self._unpack(self._bits[k]))

    def __setitem__(self, k: int, mask: Tensor | np.ndarray) -> None:
        self._bits[k] = self._pack(mask)

    def __delitem__(self, k: int) -> None:
        del self._bits[k]

    def __iter__(self):
        return (self[k] for k in range(len(self)))

    def stacked(self) -> np.ndarray:
        """(K, h, w) bool: every mask."""
        if not self._bits:
            return np.zeros((0, *self.grid), dtype=bool)
        return np.stack([self._unpack(b) for b in self._bits])


def grid_image(image: np.ndarray, grid: tuple[int, int]) -> Tensor:
    """Working-size RGB uint8 (H, W, 3) → (h, w, 3) uint8 on the BA grid (area average)."""
    return torch.from_numpy(cv2.resize(image, (grid[1], grid[0]), interpolation=cv2.INTER_AREA))


def observed_disparity(disps: Tensor, prior: Tensor | None) -> Tensor:
    """The disparity the consistency test trusts: the sensor's where a prior exists (0 = unknown), else BA's."""
    return disps if prior is None else prior


class KeyframeMasks:
    """Dynamic masks of the keyframes, and scene-consistency detection for new ones.

    ``consistency`` False keeps only the record (for the epipolar masks and the map).
    ``keep_flow``: keep the short edges' grid flow for the monocular output masks
    (:mod:`~droidw_cli.dynamics.posthoc`), until :meth:`finalise` turns a keyframe's
    edges into its mask.
    """

    def __init__(self, cfg: DynamicsConfig, grid: tuple[int, int], consistency: bool,
                 params: DetectionParams | None = None, keep_flow: bool = False) -> None:
        self.cfg = cfg
        self.grid = grid
        self.consistency = consistency
        self.params = params or DetectionParams()
        self.segmenter = get_segmenter(cfg.segmenter, self.params) if consistency else None
        self.images: list[Tensor] = []  # (h, w, 3) uint8 on the grid: 9 KB a keyframe at 48 × 64, see image()
        self.masks = PackedMasks(grid)  # union of every mask ever given (the map leaves these out)
        self.current = PackedMasks(grid)  # the latest consistency mask (BA zeroes these)
        self.times: list[float] = []  # keyframe timestamps (object motion over time)
        self.keep_flow = keep_flow
        # grid flow of the short edges (|i − j| ≤ EDGE_SPAN): (i, j) → (target p*_ij (h, w, 2) float16 in grid
        # px of j, confidence (h, w) uint8 in 1/255); 15 KB an edge, about 60 KB a keyframe, kept only until the
        # keyframe's poses are final (finalise), so bounded by the global BA's horizon
        self.edges: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self.final = PackedMasks(grid)  # the monocular output masks of keyframes [0, len(final)), see finalise
        # of the settled keyframes' edges (k, k ± 1) only where each pixel's match lands (match_index), int16,
        # 6 KB an edge: the object ids of the final pass carry objects along them
        self.matches: dict[tuple[int, int], np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.masks)

    def append(self, image: np.ndarray, timestamp: float | None = None) -> None:
        """Register a new keyframe (its working-size image and timestamp)."""
        self.images.append(grid_image(image, self.grid))
        self.times.append(float(len(self.times) if timestamp is None else timestamp))
        self.masks.append(np.zeros(self.grid, dtype=bool))
        self.current.append(np.zeros(self.grid, dtype=bool))

    def image(self, k: int) -> Tensor:
        """Keyframe k's colour on the grid, (h, w, 3) float32 in [0, 1]."""
        return self.images[k].float() / 255.0

    def remove(self, k: int) -> None:
        """Keyframe removal: drop k, the later keyframes move down by one (a k never registered is ignored)."""
        if k >= len(self.masks):
            return
        del self.images[k]
        del self.masks[k]
        del self.current[k]
        del self.times[k]
        if k < len(self.final):
            del self.final[k]

        def renumber(i: int) -> int:
            return i - (i > k)

        self.edges = {(renumber(a), renumber(b)): v for (a, b), v in self.edges.items() if k not in (a, b)}
        self.matches = {(renumber(a), renumber(b)): v for (a, b), v in self.matches.items() if k not in (a, b)}

    def record(self, k: int, mask: Tensor | np.ndarray) -> None:
        """Add ``mask`` (h, w) to keyframe k's union of dynamic masks."""
        self.masks[k] |= torch.as_tensor(np.asarray(mask, dtype=bool))

    def keep_edge(self, i: int, j: int, target: Tensor, weight: Tensor) -> None:
        """Keep the grid flow of edge i → j when it is short (``EDGE_SPAN``); target (h, w, 2), weight (h, w[, 2])."""
        if not self.keep_flow or abs(i - j) > EDGE_SPAN or i < len(self.final):
            return
        w = weight.detach().cpu().float()
        w = w[..., 0] if w.dim() == 3 else w
        self.edges[(i, j)] = (target.detach().cpu().numpy().astype(np.float16),
                              np.round(w.clamp(0, 1).numpy() * 255).astype(np.uint8))

    def finalise(self, hi: int, poses_w2c: Tensor, disps: Tensor, intrinsics: Tensor) -> None:
        """Keyframes [len(final), hi) have their final poses: their monocular output masks from the kept edges
        under these poses (``poses_w2c`` (K, 7) and observed ``disps`` (K, h, w) of keyframes [0, K)), and their
        edges are dropped.  Without ``keep_flow`` nothing happens."""
        lo = len(self.final)
        if not self.keep_flow or hi <= lo:
            return
        for m in motion_masks(self.edges, poses_w2c, disps, intrinsics, range(lo, hi)):
            self.final.append(m)
        for (i, j) in [key for key in self.edges if key[0] < hi and abs(key[0] - key[1]) == 1]:
            self.matches[(i, j)] = self.match_index(i, j)
        self.edges = {key: v for key, v in self.edges.items() if key[0] >= hi}

    def match_index(self, i: int, j: int) -> np.ndarray | None:
        """(h, w) int16 (int32 on grids over 32767 cells): the flat grid index in keyframe j of each pixel's rounded match p*_ij on the kept
        edge i → j, −1 where it leaves the grid; None without that edge."""
        if (i, j) in self.matches:
            return self.matches[(i, j)]
        edge = self.edges.get((i, j))
        if edge is None:
            return None
        h, w = self.grid
        xy = np.rint(edge[0].astype(np.float32)).astype(np.int64)
        inside = (xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)
        return np.where(inside, xy[..., 1] * w + xy[..., 0], -1).astype(np.int16 if h * w <= 32767 else np.int32)

    def output_masks(self, poses_w2c: Tensor, disps: Tensor, intrinsics: Tensor) -> list[Tensor]:
        """Every keyframe's monocular output mask: :meth:`finalise` on the ones not final yet."""
        self.finalise(len(self), poses_w2c, disps, intrinsics)
        return list(self.final)

    def set_current(self, k: int, mask: Tensor | None) -> None:
        """Keyframe k's consistency mask for BA is now ``mask`` (None: no mask); it also joins the record."""
        current = torch.zeros(self.grid, dtype=torch.bool) if mask is None else mask.detach().cpu().bool()
        self.current[k] = current
        self.masks[k] |= current

    def sources(self, k: int, n: int) -> list[int]:
        """The ``consistency_sources`` keyframes before k (after k for the first keyframe) among the first n."""
        m = self.cfg.consistency_sources
        before = list(range(max(0, k - m), k))
        return before if before else list(range(k + 1, min(n, k + 1 + m)))

    def detect(self, k: int, poses_w2c: Tensor, disps: Tensor, intrinsics: Tensor,
               sources: list[int]) -> Objects | None:
        """Scene-consistency objects of keyframe k against ``sources``; None when not usable.

        ``poses_w2c`` (K, 7), ``disps`` (K, h, w) (observed disparities, see
        :func:`observed_disparity`) and ``intrinsics`` (4,) of the grid, any device.
        """
        if not sources or self.segmenter is None:
            return None
        idx = [*sources, k]
        images = torch.stack([self.image(i) for i in idx])
        d = disps[idx].detach().float().cpu()
        g = poses_w2c[idx].detach().float().cpu()
        kk = intrinsics.detach().float().cpu()
        t = len(sources)
        pred_rgb, pred_disp, valid = predict_views(images, d, g, kk, t, list(range(t)), self.params.min_depth,
                                                   self.params.depth_mode)
        maps = inconsistency(images[t], d[t], pred_rgb, pred_disp, valid, self.cfg.tau_scale, self.params)
        if float(maps.m_dyn.float().mean()) > MAX_MASKED:
            return None
        depth = torch.where(d[t] > 0, 1.0 / d[t].clamp(min=1e-6), torch.zeros_like(d[t]))
        objects = self.segmenter.segment(maps.m_dyn, images[t], depth, focal=(float(kk[0]), float(kk[1])))
        if float(objects.mask.float().mean()) > MAX_MASKED:
            return None
        return objects

    def stacked(self) -> np.ndarray:
        """(K, h, w) bool: every keyframe's union mask."""
        return self.masks.stacked()
