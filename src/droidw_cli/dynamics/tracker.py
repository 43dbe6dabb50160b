"""Frame-to-frame identities of dynamic objects (ADD-SLAM's dynamic object tracking, simplified).

Each frame's dynamic mask is split into 8-connected components with
inscribed-circle centres (:mod:`droidw_cli.dynamics.refine`).  Active tracks
are visited in id order; track i with previous centre c_i and area a_i is
matched to

1. the unclaimed component containing pixel round(c_i), else
2. the unclaimed component whose centre is nearest to c_i, if closer than
   ``max_jump · w``;

otherwise the track ends ("lost").  A matched track ends when

* its new centre lies within ``border · w`` (x) or ``border · h`` (y) of the
  image border ("border"),
* its area grows by more than ``max_growth``× in one frame ("growth"), or
* its centre moves more than ``max_jump · w`` in one frame ("jump").

Components left unclaimed, or released by a "growth"/"jump" ending, start new
tracks with fresh ids unless their centre is at the border.  Backtracking to
label earlier frames is left to the caller (the tracker keeps no history).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import torch
from torch import Tensor

from droidw_cli.dynamics.refine import label_components, make_objects


@dataclass(frozen=True)
class TrackedObject:
    """One object in one frame: id, mask (h, w) bool numpy, centre (x, y), area (pixels)."""

    id: int
    mask: np.ndarray
    centre: tuple[float, float]
    area: int


@dataclass(frozen=True)
class TrackEnd:
    """A finished track: its id, the frame at which it ended, and why (lost/border/growth/jump)."""

    id: int
    frame: int
    reason: str


@dataclass
class DynamicObjectTracker:
    """Keeps object ids across frames; call :meth:`update` once per frame with its dynamic mask."""

    border: float = 0.04
    max_growth: float = 1.5
    max_jump: float = 0.2
    min_area: int = 1
    active: dict[int, TrackedObject] = field(default_factory=dict)
    ended: list[TrackEnd] = field(default_factory=list)
    frame: int = -1
    _next_id: int = 0

    def _at_border(self, centre: np.ndarray, h: int, w: int) -> bool:
        x, y = float(centre[0]), float(centre[1])
        return min(x, w - 1 - x) < self.border * w or min(y, h - 1 - y) < self.border * h

    def _new(self, mask: np.ndarray, centre: np.ndarray, area: int) -> TrackedObject:
        obj = TrackedObject(self._next_id, mask, (float(centre[0]), float(centre[1])), area)
        self._next_id += 1
        return obj

    def update(self, mask, predicted: dict[int, tuple[float, float]] | None = None) -> list[TrackedObject]:
        """Track the components of a (h, w) bool mask; returns the active objects of this frame.

        ``predicted``: optional centre of some active tracks in this frame, used in place of
        their previous centre for the match and the jump test.
        """
        m = torch.as_tensor(np.asarray(mask.detach().cpu() if isinstance(mask, Tensor) else mask)).bool()
        if m.dim() != 2:
            raise ValueError(f"mask must be (h, w), got shape {tuple(m.shape)}")
        h, w = m.shape
        self.frame += 1
        objs = make_objects(label_components(m, self.min_area))
        labels = objs.labels.numpy()
        centres, areas = objs.centres.numpy(), objs.areas.numpy()
        claimed = np.zeros(objs.count, dtype=bool)
        free = np.zeros(objs.count, dtype=bool)  # released components that may start new tracks
        new_active: dict[int, TrackedObject] = {}
        for tid in sorted(self.active):
            prev = self.active[tid]
            if predicted is not None and tid in predicted:
                prev = TrackedObject(prev.id, prev.mask, predicted[tid], prev.area)
            px, py = int(round(prev.centre[0])), int(round(prev.centre[1]))
            c = -1
            if 0 <= px < w and 0 <= py < h and labels[py, px] > 0 and not claimed[labels[py, px] - 1]:
                c = int(labels[py, px]) - 1
            elif objs.count:
                dist = np.hypot(centres[:, 0] - prev.centre[0], centres[:, 1] - prev.centre[1])
                dist[claimed] = np.inf
                best = int(np.argmin(dist))
                if dist[best] <= self.max_jump * w:
                    c = best
            if c < 0:
                self.ended.append(TrackEnd(tid, self.frame, "lost"))
                continue
            claimed[c] = True
            jump = float(np.hypot(centres[c, 0] - prev.centre[0], centres[c, 1] - prev.centre[1]))
            if self._at_border(centres[c], h, w):
                self.ended.append(TrackEnd(tid, self.frame, "border"))
            elif areas[c] > self.max_growth * prev.area:
                self.ended.append(TrackEnd(tid, self.frame, "growth"))
                free[c] = True
            elif jump > self.max_jump * w:
                self.ended.append(TrackEnd(tid, self.frame, "jump"))
                free[c] = True
            else:
                new_active[tid] = TrackedObject(tid, labels == c + 1, (float(centres[c, 0]), float(centres[c, 1])),
                                                int(areas[c]))
        for c in np.flatnonzero(~claimed | free):
            if not self._at_border(centres[c], h, w):
                obj = self._new(labels == c + 1, centres[c], int(areas[c]))
                new_active[obj.id] = obj
        self.active = new_active
        return [new_active[k] for k in sorted(new_active)]
