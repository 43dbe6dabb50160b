"""The frame graph: which keyframe pairs (i, j) become BA edges, and their targets.

Edges are directed: pixels of keyframe i are matched into keyframe j.  Every
pair is added in both directions.  Correspondence targets are computed once
per edge by the correspondence source and cached at 1/8 resolution (targets
in float32, confidences in float16), so the final global BA can reuse them
without keeping images.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch
from torch import Tensor

from droidw_cli.ba.types import EdgeSet


@dataclass
class EdgeCache:
    """Correspondence targets and confidences per directed keyframe edge (i, j)."""

    targets: dict[tuple[int, int], tuple[Tensor, Tensor]] = field(default_factory=dict)

    def __contains__(self, key: tuple[int, int]) -> bool:
        return key in self.targets

    def __len__(self) -> int:
        return len(self.targets)

    def put(self, i: int, j: int, target: Tensor, weight: Tensor) -> None:
        self.targets[(i, j)] = (target.to(torch.float32), weight.to(torch.float16))

    def pairs(self) -> list[tuple[int, int]]:
        return list(self.targets.keys())

    def edge_set(self, pairs: list[tuple[int, int]], offset: int = 0) -> EdgeSet:
        """Stack cached edges into an :class:`EdgeSet` with indices shifted by ``-offset``."""
        ii = torch.tensor([p[0] - offset for p in pairs], dtype=torch.long)
        jj = torch.tensor([p[1] - offset for p in pairs], dtype=torch.long)
        target = torch.stack([self.targets[p][0] for p in pairs]).float()
        weight = torch.stack([self.targets[p][1] for p in pairs]).float()
        return EdgeSet(ii, jj, target, weight)


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


def select_proximity(k: int, candidates: list[int], mean_flow: Tensor, thresh: float, limit: int) -> list[tuple[int, int]]:
    """Proximity edges from keyframe k to the candidates whose induced mean flow is below ``thresh``.

    ``mean_flow`` (len(candidates),) holds the induced flow magnitude k → candidate.
    The closest (smallest flow) come first; at most ``limit`` pairs, both directions.
    """
    order = torch.argsort(mean_flow)
    out = []
    for idx in order.tolist():
        if float(mean_flow[idx]) >= thresh or len(out) >= 2 * limit:
            break
        j = candidates[idx]
        out += [(k, j), (j, k)]
    return out


def cap_edges(pairs: list[tuple[int, int]], max_edges: int) -> list[tuple[int, int]]:
    """Keep at most ``max_edges`` edges, dropping the oldest (smallest max(i, j)) first."""
    if len(pairs) <= max_edges:
        return pairs
    return sorted(pairs, key=lambda p: (max(p), min(p)))[-max_edges:]
