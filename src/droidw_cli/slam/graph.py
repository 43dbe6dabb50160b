"""The frame graph: which keyframe pairs (i, j) become BA edges, and their targets.

Edges are directed: pixels of keyframe i are matched into keyframe j.  Every
pair is added in both directions.  Correspondence targets are computed once
per edge by the correspondence source and cached at 1/8 resolution (targets
in float32, confidences in float16, the rows of one slab), so the final global BA can reuse them
without keeping images.  The cache lives on the BA backend's device: each
edge's target and confidence are copied there once, when they are stored.
"""

from __future__ import annotations

import torch
from torch import Tensor

from droidw_cli.ba.types import EdgeSet
from droidw_cli.runtime.slab import RowSlab


class EdgeCache:
    """Correspondence targets and confidences per directed keyframe edge (i, j).

    ``born`` holds the BA iteration count at which each edge was added, so
    that the window BA can retire edges after ``max_age`` iterations (the
    global BA still uses them all).  Targets, confidences and the index
    tensors of :meth:`edge_set` are on ``device``.  They are the rows of one
    :class:`~droidw_cli.runtime.slab.RowSlab` (one row per edge, reused once the
    edge is forgotten), not tensors of their own, which left holes in the heap
    over a long video.
    """

    def __init__(self, device: torch.device | str = "cpu"):
        self.device = torch.device(device)
        self.born: dict[tuple[int, int], int] = {}
        self._row: dict[tuple[int, int], int] = {}  # edge → its slab row
        self._slab = RowSlab((torch.float32, torch.float16), self.device, min_grow=256)

    def __contains__(self, key: tuple[int, int]) -> bool:
        return key in self._row

    def __len__(self) -> int:
        return len(self._row)

    @property
    def nbytes(self) -> int:
        """Bytes of the slab (the edges' rows and the free ones)."""
        return self._slab.nbytes

    def put(self, i: int, j: int, target: Tensor, weight: Tensor, born: int | None = None) -> None:
        """Store (or overwrite) edge (i, j): its target (float32) and confidence (float16)."""
        key = (i, j)
        if key in self._row:
            self._slab.write(self._row[key], target, weight)
        else:
            self._row[key] = self._slab.store(target, weight)
        if born is not None or key not in self.born:
            self.born[key] = 0 if born is None else born

    def target(self, key: tuple[int, int]) -> Tensor:
        """Edge ``key``'s target (a read-only view, valid until the next :meth:`put`)."""
        return self._slab.row(self._row[key])[0]

    def weight(self, key: tuple[int, int]) -> Tensor:
        """Edge ``key``'s confidence, float16 (a read-only view, valid until the next :meth:`put`)."""
        return self._slab.row(self._row[key])[1]

    def pairs(self) -> list[tuple[int, int]]:
        return list(self._row.keys())

    def young_pairs(self, now: int, max_age: int, lo: int = 0) -> list[tuple[int, int]]:
        """Pairs with both ends ≥ lo added at most ``max_age`` iterations before ``now``."""
        return [p for p, b in self.born.items() if min(p) >= lo and now - b <= max_age]

    def _forget(self, keep) -> None:
        """Release the rows of the edges ``keep(p)`` rejects."""
        kept = {}
        for p, row in self._row.items():
            if keep(p):
                kept[p] = row
            else:
                self._slab.release(row)
        self._row = kept
        self.born = {p: v for p, v in self.born.items() if p in kept}

    def remove_frame(self, k: int) -> None:
        """Forget keyframe k's edges and renumber the later keyframes down by one."""
        def shift(p: tuple[int, int]) -> tuple[int, int]:
            return (p[0] - (p[0] > k), p[1] - (p[1] > k))

        self._forget(lambda p: k not in p)
        self._row = {shift(p): v for p, v in self._row.items()}
        self.born = {shift(p): v for p, v in self.born.items()}

    def drop_before(self, lo: int) -> None:
        """Forget every edge with an end before keyframe ``lo`` (it left the bounded global problem)."""
        self._forget(lambda p: min(p) >= lo)

    def edge_set(self, pairs: list[tuple[int, int]], offset: int = 0) -> EdgeSet:
        """Stack cached edges into an :class:`EdgeSet` with indices shifted by ``-offset``."""
        ii = torch.tensor([p[0] - offset for p in pairs], dtype=torch.long, device=self.device)
        jj = torch.tensor([p[1] - offset for p in pairs], dtype=torch.long, device=self.device)
        target, weight = self._slab.rows([self._row[p] for p in pairs])
        return EdgeSet(ii, jj, target, weight.float())


def radius_pairs(k: int, lo: int, radius: int) -> list[tuple[int, int]]:
    """Pairs between the new keyframe k and its ``radius`` predecessors (≥ lo), both directions."""
    out = []
    for d in range(1, radius + 1):
        j = k - d
        if j < lo:
            break
        out += [(k, j), (j, k)]
    return out


def init_pairs(n: int, radius: int) -> list[tuple[int, int]]:
    """All pairs among the first n keyframes within ``radius`` of each other, both directions."""
    return [(i, j) for i in range(n) for j in range(n) if i != j and abs(i - j) <= radius]


def select_proximity(candidates: list[tuple[int, int]], distance: Tensor, thresh: float, nms: int,
                     existing: set[tuple[int, int]], limit: int) -> list[tuple[int, int]]:
    """Proximity pairs (DROID-SLAM): the closest candidate pairs under ``thresh``, with non-maximum suppression.

    ``candidates`` are unordered pairs (i, j) and ``distance`` their frame
    distances.  A pair is suppressed when it lies within ``nms`` keyframes of
    an existing or already chosen pair, i.e. |i − i'| ≤ nms and |j − j'| ≤ nms
    (in either orientation).  At most ``limit`` pairs; returned both directions.
    ``distance`` may be on any device: it is read back once.
    """
    taken = {(min(p), max(p)) for p in existing}
    values = distance.tolist()

    def suppressed(i: int, j: int) -> bool:
        return any(abs(i - a) <= nms and abs(j - b) <= nms for a, b in taken)

    out: list[tuple[int, int]] = []
    for idx in torch.argsort(distance).tolist():
        if values[idx] >= thresh or len(out) >= 2 * limit:
            break
        i, j = sorted(candidates[idx])
        if suppressed(i, j):
            continue
        taken.add((i, j))
        out += [(i, j), (j, i)]
    return out


def cap_edges(pairs: list[tuple[int, int]], max_edges: int) -> list[tuple[int, int]]:
    """Keep at most ``max_edges`` edges, dropping the oldest (smallest max(i, j)) first."""
    if len(pairs) <= max_edges:
        return pairs
    return sorted(pairs, key=lambda p: (max(p), min(p)))[-max_edges:]
