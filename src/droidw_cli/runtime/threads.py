"""Torch's intra-op threads for the BA: one core left free while other stages run, all when nothing else does.

The tracker's first pass runs DIS, the motion filter, decoding and feature
extraction on worker threads beside the main thread's window BA, so the BA
gets one core less than the machine has (on 2 cores: one; two torch threads
stall whenever anything else runs, see ``TrackConfig.threads``).  The global
BA (periodic and final) and the steps after the first pass run with the
workers idle: there every usable core is the BA's.  Measured on rotate
seed 1, 2 cores (2026-11-27): the global BA took 3.7 s instead of 5.2, and
``traj.txt`` was identical to the byte.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager

import torch

#: torch never gets more intra-op threads than this by default
MAX_THREADS = 8


def usable_cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def torch_threads(requested: int, alone: bool = False) -> int:
    """Torch threads for ``threads`` = requested: itself when > 0, else the usable cores − 1 (``alone``:
    nothing else runs beside the BA, so all of them), clamped to 1 … ``MAX_THREADS``."""
    if requested > 0:
        return requested
    return max(1, min(usable_cores() - (0 if alone else 1), MAX_THREADS))


@contextmanager
def torch_threads_set(count: int) -> Iterator[None]:
    """Run the block with ``count`` torch intra-op threads, then restore the previous count."""
    before = torch.get_num_threads()
    torch.set_num_threads(max(1, int(count)))
    try:
        yield
    finally:
        torch.set_num_threads(before)
