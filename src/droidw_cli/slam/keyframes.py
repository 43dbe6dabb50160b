"""The keyframe buffer: 1/8-resolution state per keyframe, in growable tensors.

Per keyframe t it keeps the source frame index and timestamp, the pose G_t
(world-to-camera, (7,)), the inverse depth d_t (h, w), optional features F_t
(C, h, w, float16), an optional prior disparity D_t (allocated with the first
prior, so monocular runs keep none), and an RGB thumbnail.
Nothing at the working resolution is kept here.  The features are the bulk
(64 × h × w float16, ~390 KB at 48 × 64): once a keyframe leaves the bounded
global problem, :meth:`KeyframeBuffer.archive` replaces them by the frozen
uncertainty map u_t (h × w float16); thumbnails are kept JPEG-encoded.

The tensors live on ``device``, the BA backend's (:attr:`BABackend.device`),
from the start: a keyframe's pose, disparity, features and prior are copied
there once, in :meth:`KeyframeBuffer.append`; the thumbnails stay on the host.
A keyframe's features may also be *pending*, an object whose ``result()``
gives them (a :class:`concurrent.futures.Future` of a feature extractor
running on another thread): they are fetched the first time they are read.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from droidw_cli.io.jpeg import decode_rgb, encode_rgb

#: JPEG quality of the stored thumbnails (37 KB raw at 96 × 128 → a few KB; a long video keeps thousands)
THUMBNAIL_QUALITY = 95


class KeyframeBuffer:
    """Growable storage for keyframe state (capacity doubles when full)."""

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
        self.frozen_u: dict[int, Tensor] = {}  # archived keyframe → its uncertainty map (h, w) float16
        self.frozen_conf: dict[int, Tensor] = {}  # archived keyframe → its mean edge confidence (h, w) float16
        self.frame_index: list[int] = []
        self.timestamps: list[float] = []
        self.thumbnails: list[np.ndarray] = []  # JPEG bytes (quality THUMBNAIL_QUALITY), see thumbnail()
        self.has_prior = False

    def __len__(self) -> int:
        return self.count

    def _grow(self) -> None:
        def grown(t: Tensor, fill: float) -> Tensor:
            extra = torch.full_like(t, fill)
            return torch.cat([t, extra], 0)

        new_poses = grown(self.poses, 0.0)
        new_poses[self.poses.shape[0]:, 6] = 1.0
        self.poses = new_poses
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
            self.features.append(self._stored(features) if isinstance(features, Tensor) else features)
        if depth_prior is not None:
            if self.depth_prior is None:
                self.depth_prior = torch.zeros_like(self.disps)
            self.depth_prior[k] = depth_prior.to(self.device)
            self.has_prior = True
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
            del self.features[k]
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

    def thumbnail_stack(self) -> np.ndarray:
        """(K, H/s, W/s, 3) uint8: every thumbnail, decoded into one array."""
        if not self.count:
            return np.zeros((0, 1, 1, 3), np.uint8)
        out = np.empty((self.count, *self._thumb_shape), np.uint8)
        for k in range(self.count):
            out[k] = self.thumbnail(k)
        return out

    def feature_block(self, lo: int, hi: int) -> Tensor:
        """Features (hi − lo, C, h, w) of keyframes [lo, hi), none of them archived."""
        block = self.features[lo:hi]
        if any(f is None for f in block):
            raise ValueError(f"keyframes in [{lo}, {hi}) were archived: their features are gone")
        for k, f in enumerate(block):
            if not isinstance(f, Tensor):  # pending: fetch them once
                block[k] = self.features[lo + k] = self._stored(f.result())
        return torch.stack(block)

    def _stored(self, features: Tensor) -> Tensor:
        return features.to(device=self.device, dtype=self.feature_dtype)

    def archive(self, k: int, uncertainty: Tensor | None, confidence: Tensor) -> None:
        """Keyframe k left the optimisation for good: keep its u and confidence maps, drop its features."""
        if uncertainty is not None:
            self.frozen_u[k] = uncertainty.to(torch.float16)
        self.frozen_conf[k] = confidence.to(torch.float16)
        if self.features is not None:
            self.features[k] = None
