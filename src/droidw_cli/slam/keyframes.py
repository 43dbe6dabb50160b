"""The keyframe buffer: 1/8-resolution state per keyframe, in growable tensors.

Per keyframe t it keeps the source frame index and timestamp, the pose G_t
(world-to-camera, (7,)), the inverse depth d_t (h, w), optional features F_t
(C, h, w, float16), an optional prior disparity D_t (allocated with the first
prior, so monocular runs keep none), and an RGB thumbnail.
Nothing at the working resolution is kept here.  The features are the bulk
(64 × h × w float16, ~390 KB at 48 × 64): once a keyframe leaves the bounded
global problem, :meth:`KeyframeBuffer.archive` replaces them by the frozen
uncertainty map u_t (h × w float16); thumbnails are kept JPEG-encoded.
The stored features are the rows of one :class:`~droidw_cli.runtime.slab.RowSlab`
(an archived keyframe's row is reused by a later keyframe), not tensors of
their own, which left holes in the heap over a long video.

The tensors live on ``device``, the BA backend's (:attr:`BABackend.device`),
from the start: a keyframe's pose, disparity, features and prior are copied
there once, in :meth:`KeyframeBuffer.append`; the thumbnails stay on the host.
A keyframe's features may also be *pending*, an object whose ``result()``
gives them (a :class:`concurrent.futures.Future` of a feature extractor
running on another thread): they are fetched the first time they are read.

Memory against video length: the pose/disparity/prior tensors grow by a
quarter (at least ``GROW_MIN`` rows) into a fresh tensor that the old rows are
copied into, so a long video holds at most 25 % slack and a growth step needs
the old plus the new tensor (2.25× the rows), not the 3× of doubling with
``torch.cat`` (old, the appended block and the result).  At 48 × 64 the
disparity row is 12 KB: 2000 keyframes are 24 MB.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from droidw_cli.io.jpeg import JpegStack, decode_rgb, encode_rgb
from droidw_cli.runtime.slab import RowSlab

#: JPEG quality of the stored thumbnails (37 KB raw at 96 × 128 → a few KB; a long video keeps thousands)
THUMBNAIL_QUALITY = 95
#: the capacity grows by GROW_FACTOR, by at least GROW_MIN keyframes
GROW_FACTOR = 1.25
GROW_MIN = 64
#: :meth:`KeyframeBuffer.feature_block` keeps the float32 channels-last rows of blocks up to this many keyframes
#: (a window: at most ``frontend.window_max`` 35; 0.75 MB each at 48 × 64 × 64) for the next window
ROWS_CACHED = 48


def grown_capacity(capacity: int) -> int:
    """The next capacity after ``capacity`` (full): +25 %, at least +GROW_MIN."""
    return max(capacity + GROW_MIN, int(capacity * GROW_FACTOR))


class KeyframeBuffer:
    """Growable storage for keyframe state (capacity grows by :func:`grown_capacity` when full)."""

    def __init__(self, grid: tuple[int, int], feature_channels: int = 0, feature_dtype=torch.float16,
                 capacity: int = 64, device: torch.device | str = "cpu"):
        self.grid = grid
        self.count = 0
        self.device = torch.device(device)
        h, w = grid
        dev = self.device
        self.poses = torch.zeros(capacity, 7, device=dev)
        self.poses[:, 6] = 1.0
        self.disps = torch.ones(capacity, h, w, device=dev)
        self.depth_prior: Tensor | None = None  # allocated with the first prior (RGB-D); monocular runs keep none
        self.feature_dtype = feature_dtype
        self.features: list | None = [] if feature_channels else None  # Tensor, pending, or None: archived
        # the stored features are rows of one slab (runtime/slab.py): the slab row of each keyframe's, or None
        self._feature_slab = RowSlab((feature_dtype,), self.device, GROW_MIN) if feature_channels else None
        self._feature_row: list[int | None] = []
        self.frozen_u: dict[int, Tensor] = {}  # archived keyframe → its uncertainty map (h, w) float16
        self.frozen_conf: dict[int, Tensor] = {}  # archived keyframe → its mean edge confidence (h, w) float16
        self.frame_index: list[int] = []
        self.timestamps: list[float] = []
        self.thumbnails: list[np.ndarray] = []  # JPEG bytes (quality THUMBNAIL_QUALITY), see thumbnail()
        self._thumb_shape: tuple[int, ...] = (1, 1, 3)  # of the decoded thumbnails
        self.has_prior = False
        # id(stored features) → (them, their channels-last rows (HW, C)) for the last window's keyframes
        self._rows: dict[int, tuple[Tensor, Tensor]] = {}
        self._last_block: tuple[tuple, torch.dtype, Tensor] | None = None  # (its features, dtype, the block)

    def __len__(self) -> int:
        return self.count

    @property
    def capacity(self) -> int:
        return self.poses.shape[0]

    def _grow(self) -> None:
        """Room for more keyframes: a larger tensor per field, the old rows copied in, the rest filled."""
        old, new = self.capacity, grown_capacity(self.capacity)

        def grown(t: Tensor, fill: float) -> Tensor:
            out = t.new_empty((new, *t.shape[1:]))
            out[:old].copy_(t)
            out[old:].fill_(fill)
            return out

        poses = grown(self.poses, 0.0)
        poses[old:, 6] = 1.0
        self.poses = poses
        self.disps = grown(self.disps, 1.0)
        if self.depth_prior is not None:
            self.depth_prior = grown(self.depth_prior, 0.0)

    def append(self, frame_index: int, timestamp: float, pose: Tensor, disp: Tensor | float,
               thumbnail: np.ndarray, features: Tensor | None = None, depth_prior: Tensor | None = None) -> int:
        """Add a keyframe; returns its buffer index."""
        if self.count == self.poses.shape[0]:
            self._grow()
        k = self.count
        self.poses[k] = pose
        self.disps[k] = disp
        if self.features is not None:
            if features is None:
                raise ValueError("this buffer keeps features: every keyframe needs them")
            self.features.append(features)
            self._feature_row.append(None)
            if isinstance(features, Tensor):
                self._store_features(k, features)
        if depth_prior is not None:
            if self.depth_prior is None:
                self.depth_prior = torch.zeros_like(self.disps)
            self.depth_prior[k] = depth_prior.to(self.device)
            self.has_prior = self.has_prior or bool((depth_prior > 0).any())  # all-invalid depth fixes no scale
        self.frame_index.append(int(frame_index))
        self.timestamps.append(float(timestamp))
        self.thumbnails.append(encode_rgb(thumbnail, THUMBNAIL_QUALITY))
        self._thumb_shape = thumbnail.shape
        self.count += 1
        return k

    def remove(self, k: int) -> None:
        """Drop keyframe k; the later ones move down by one (DROID's keyframe removal)."""
        if not 0 <= k < self.count:
            raise IndexError(f"keyframe {k} out of range [0, {self.count})")
        n = self.count
        if self.features is not None:
            if self._feature_row[k] is not None:
                self._feature_slab.release(self._feature_row[k])
            del self.features[k], self._feature_row[k]
        self.frozen_u = {i - (i > k): u for i, u in self.frozen_u.items() if i != k}
        self.frozen_conf = {i - (i > k): c for i, c in self.frozen_conf.items() if i != k}
        for t in (self.poses, self.disps, self.depth_prior):
            if t is not None:
                t[k:n - 1] = t[k + 1:n].clone()
        self.poses[n - 1] = 0.0
        self.poses[n - 1, 6] = 1.0
        self.disps[n - 1] = 1.0
        for seq in (self.frame_index, self.timestamps, self.thumbnails):
            del seq[k]
        self.count -= 1

    def thumbnail(self, k: int) -> np.ndarray:
        """Keyframe k's RGB thumbnail (decoded; JPEG at quality THUMBNAIL_QUALITY)."""
        return decode_rgb(self.thumbnails[k])

    def thumbnail_stack(self) -> JpegStack:
        """(K, H/s, W/s, 3) uint8: every thumbnail, still encoded (``np.asarray`` decodes them all)."""
        return JpegStack(self.thumbnails[:self.count], self._thumb_shape)

    def feature_block(self, lo: int, hi: int, dtype: torch.dtype | None = None,
                      channels_last: bool = False) -> Tensor:
        """Features (hi − lo, C, h, w) of keyframes [lo, hi), none of them archived.

        ``dtype`` (default: the stored one) converts each keyframe straight into the
        result, without a stacked copy in the stored dtype on the way (200 keyframes
        of 64 × 48 × 64 float16 are 78 MB).  ``channels_last`` lays the result out as
        (N, H, W, C) in memory, converted one keyframe at a time as the CPU backend's
        feature table does (a converting transpose is several times slower).  Blocks of up
        to ``ROWS_CACHED`` keyframes keep their converted rows for the next call, which a
        window shares all but one or two keyframes with, and a call for exactly the last
        block's keyframes returns that block (read-only, as the backends treat it): rotate
        seed 2, 1.9 → 0.9 s of this call's time, the same trajectory.
        """
        block = self.features[lo:hi]
        if any(f is None for f in block):
            raise ValueError(f"keyframes in [{lo}, {hi}) were archived: their features are gone")
        for k, f in enumerate(block):
            if not isinstance(f, Tensor):  # pending: fetch them once
                block[k] = self._store_features(lo + k, f.result())
        dtype = self.feature_dtype if dtype is None else dtype
        if not block or (dtype == self.feature_dtype and not channels_last):
            return torch.stack(block)
        c, h, w = block[0].shape
        if not channels_last:
            out = torch.empty((len(block), c, h, w), dtype=dtype, device=self.device)
            for row, f in zip(out, block):
                row.copy_(f)
            return out
        last = self._last_block
        if last is not None and last[1] == dtype and len(last[0]) == len(block) and all(
                a is b for a, b in zip(last[0], block)):
            return last[2]  # the same keyframes as the last call (a window's second round of iterations)
        rows = torch.empty(len(block), h * w, c, dtype=dtype, device=self.device)
        frame = torch.empty(c, h * w, dtype=dtype, device=self.device)
        kept = {}
        for row, f in zip(rows, block):
            hit = self._rows.get(id(f))
            if hit is not None and hit[0] is f and hit[1].dtype == dtype:
                row.copy_(hit[1])  # a plain copy: the converting transpose is most of this call's time
            else:
                frame.copy_(f.reshape(c, h * w))
                row.copy_(frame.t())
                hit = (f, row.clone()) if len(block) <= ROWS_CACHED else None
            if hit is not None:
                kept[id(f)] = hit
        out = rows.view(len(block), h, w, c).permute(0, 3, 1, 2)
        if len(block) <= ROWS_CACHED:  # a window's block: keep its keyframes' rows for the next one
            self._rows, self._last_block = kept, (tuple(block), dtype, out)
        return out

    def _store_features(self, k: int, features: Tensor) -> Tensor:
        """Keyframe k's features into a slab row (converted to the stored dtype); returns the row's view."""
        slab = self._feature_slab
        generation = slab.generation
        self._feature_row[k] = slab.store(features)
        if slab.generation != generation:  # the slab moved: point every stored keyframe at its new row
            for i, row in enumerate(self._feature_row):
                if row is not None and i != k:
                    self.features[i] = slab.row(row)[0]
            self._rows, self._last_block = {}, None
        self.features[k] = slab.row(self._feature_row[k])[0]
        return self.features[k]

    def archive(self, k: int, uncertainty: Tensor | None, confidence: Tensor) -> None:
        """Keyframe k left the optimisation for good: keep its u and confidence maps, drop its features."""
        if uncertainty is not None:
            self.frozen_u[k] = uncertainty.to(torch.float16)
        self.frozen_conf[k] = confidence.to(torch.float16)
        if self.features is not None:
            if self._feature_row[k] is not None:
                self._feature_slab.release(self._feature_row[k])
            self.features[k] = self._feature_row[k] = None
