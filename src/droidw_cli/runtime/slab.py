"""Row slabs: many same-shaped tensors kept as the rows of one growable block.

A long video stores small tensors that live for the global BA's horizon (200
keyframes) and are then freed: each keyframe's features (64 × 48 × 64 float16,
390 KB) and each edge's correspondence target and confidence (37 KB at 48 × 64).
Kept as tensors of their own, they sit in glibc's heap among the BA's
temporaries, and the holes they leave when freed are not always reused, so the
resident set creeps over a long stream although what is live stays bounded
(``docs/benchmarks.md``, "Memory: slabs").  A :class:`RowSlab` keeps them as the
rows of one block per field instead: a released row is the next one stored
(lowest first, so the used rows stay packed at the bottom), and a full block
grows by a quarter, at least ``min_grow`` rows, into a fresh one (:attr:`RowSlab.generation`
counts the moves, after which earlier :meth:`RowSlab.row` views are stale).
"""

from __future__ import annotations

import heapq
from collections.abc import Sequence

import torch
from torch import Tensor

#: a full slab grows by this factor, by at least ``min_grow`` rows
GROW_FACTOR = 1.25


class RowSlab:
    """Rows of one or more fields (one tensor each, all indexed by the same row), with a free list.

    ``dtypes``: one per field; each field's row shape is taken from the first :meth:`store`.
    """

    def __init__(self, dtypes: Sequence[torch.dtype], device: torch.device | str = "cpu", min_grow: int = 64):
        if min_grow < 1:
            raise ValueError(f"min_grow must be at least 1, got {min_grow}")
        self.dtypes = tuple(dtypes)
        self.device = torch.device(device)
        self.min_grow = int(min_grow)
        self.blocks: tuple[Tensor, ...] | None = None
        self.generation = 0  # how many times the blocks moved (views from row() taken before are stale)
        self._free: list[int] = []  # a heap of the free rows
        self._used = 0

    def __len__(self) -> int:
        return self._used

    @property
    def capacity(self) -> int:
        return 0 if self.blocks is None else int(self.blocks[0].shape[0])

    @property
    def nbytes(self) -> int:
        return 0 if self.blocks is None else sum(b.nbytes for b in self.blocks)

    def _grow(self, values: Sequence[Tensor]) -> None:
        old = self.capacity
        new = max(old + self.min_grow, int(old * GROW_FACTOR))
        blocks = []
        for f, (dtype, v) in enumerate(zip(self.dtypes, values)):
            shape = v.shape if self.blocks is None else self.blocks[f].shape[1:]
            block = torch.empty((new, *shape), dtype=dtype, device=self.device)
            if self.blocks is not None:
                block[:old].copy_(self.blocks[f])
            blocks.append(block)
        self.blocks = tuple(blocks)
        self._free.extend(range(old, new))  # ascending: still a heap
        self.generation += 1

    def store(self, *values: Tensor) -> int:
        """Copy one value per field into a free row (converted to the field's dtype); returns the row."""
        if len(values) != len(self.dtypes):
            raise ValueError(f"expected {len(self.dtypes)} values, got {len(values)}")
        if self.blocks is not None:
            for block, v in zip(self.blocks, values):
                if tuple(v.shape) != tuple(block.shape[1:]):
                    raise ValueError(f"a row has shape {tuple(block.shape[1:])}, got {tuple(v.shape)}")
        if not self._free:
            self._grow(values)
        row = heapq.heappop(self._free)
        self.write(row, *values)
        self._used += 1
        return row

    def write(self, row: int, *values: Tensor) -> None:
        """Overwrite a stored row."""
        for block, v in zip(self.blocks, values):
            block[row].copy_(v)

    def release(self, row: int) -> None:
        """Free a row for the next :meth:`store`."""
        if not 0 <= row < self.capacity:
            raise IndexError(f"row {row} out of range [0, {self.capacity})")
        heapq.heappush(self._free, int(row))
        self._used -= 1

    def row(self, row: int) -> tuple[Tensor, ...]:
        """Views of one row, one per field (stale once :attr:`generation` changes; do not write to them)."""
        return tuple(block[row] for block in self.blocks)

    def rows(self, rows: Sequence[int] | Tensor) -> tuple[Tensor, ...]:
        """Copies of the given rows, stacked, one tensor per field."""
        if self.blocks is None:
            raise IndexError("the slab is empty")
        idx = torch.as_tensor(rows, dtype=torch.long, device=self.device)
        return tuple(block.index_select(0, idx) for block in self.blocks)
