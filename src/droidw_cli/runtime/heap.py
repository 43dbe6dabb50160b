"""Hand the heap's free pages back to the operating system before each global BA.

glibc's malloc keeps memory that was freed.  The global BA allocates per-edge
temporaries of tens of MB whose sizes change from run to run, and the holes
they leave are not always reused, so over a long video the resident set at the
global BA's peak creeps upward although what is live stays bounded (the
200-keyframe horizon): on a 10-minute stream the peak rose from 1503 MB at
keyframe 220 to 1793 MB at keyframe 1000 with the same ~1800 edges in the
problem (``benchmarks/memory_probe.py``).  ``malloc_trim(0)`` releases every
free page (the top of each arena and whole free pages inside it), so each run
starts from what is live.

Inside a run, :func:`large_blocks_mapped` lowers glibc's mmap threshold
(``M_MMAP_THRESHOLD``) to 4 MB: the run's per-edge (E, HW) temporaries (22 MB
at 1800 edges on the 48 × 64 grid), whose size follows the edge count, no
longer extend the heap where no free chunk holds them (glibc consults the
threshold only then) but get mappings of their own, which go back to the
system when freed instead of leaving holes.  Smaller blocks stay on the heap: a 1 MB threshold made the
global BA 30-60 % slower (page faults on every temporary).  After the run the
free pages are handed back again and the threshold returns to 32 MB, the
ceiling of glibc's own dynamic threshold.

:func:`limit_arenas` caps glibc's arenas at two (``M_ARENA_MAX``; by default
glibc allows 8 per core): the threads that allocate beside the main one (the
prefetch and scout, the match pool, the filler's flow worker, torch's workers)
share one arena instead of each fragmenting its own.

These three together (4 MB inside runs, a trim after each run, two arenas)
took the peak of a 10-minute stream from 1762 to 1521 MB with the same
trajectory in one pair of runs, and read 1591 MB alone (``docs/benchmarks.md``,
"Memory: two arenas"); the three were not measured apart.  The long-lived
per-keyframe and per-edge tensors are now rows of a few slabs that reuse their
rows (:mod:`droidw_cli.runtime.slab`), not many small blocks freed and allocated
anew among the temporaries (1546 MB, "Memory: slabs").
Elsewhere (musl, macOS, Windows) all of this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from functools import cache

#: mallopt's parameter number of the mmap threshold (glibc malloc.h)
M_MMAP_THRESHOLD = -3
#: blocks of at least this many bytes are mapped on their own during a global BA run
RUN_MMAP_THRESHOLD = 4 * 2**20
#: mallopt's parameter number of the arena cap (glibc malloc.h)
M_ARENA_MAX = -8
#: arenas allowed: the main thread's and one that every other thread shares
ARENAS = 2
#: glibc's ceiling for its dynamic mmap threshold on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX)
DYNAMIC_MMAP_CEILING = 32 * 2**20


@cache
def _glibc(name: str, argtypes: tuple):
    """glibc's function ``name`` (returning int), or None where there is no glibc."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        fn = getattr(libc, name)
    except (OSError, AttributeError):
        return None
    fn.argtypes = list(argtypes)
    fn.restype = ctypes.c_int
    return fn


def _malloc_trim():
    return _glibc("malloc_trim", (ctypes.c_size_t,))


def _mallopt():
    return _glibc("mallopt", (ctypes.c_int, ctypes.c_int))


def limit_arenas(n: int = ARENAS) -> bool:
    """Cap glibc's arenas at ``n`` (unless ``MALLOC_ARENA_MAX`` is set); True when the cap took effect.

    glibc honours the cap for threads that get their first arena afterwards, so call it before the
    tracker starts its threads.
    """
    mallopt = _mallopt()
    if mallopt is None or "MALLOC_ARENA_MAX" in os.environ:
        return False
    return bool(mallopt(M_ARENA_MAX, int(n)))


def release_free_memory() -> bool:
    """Return the heap's free pages to the OS; True when some memory was released."""
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False


@contextmanager
def large_blocks_mapped(threshold: int = RUN_MMAP_THRESHOLD) -> Iterator[bool]:
    """Within the block, blocks of at least ``threshold`` bytes are mmapped (yields whether that took effect)."""
    mallopt = _mallopt()
    applied = mallopt is not None and bool(mallopt(M_MMAP_THRESHOLD, int(threshold)))
    try:
        yield applied
    finally:
        if applied:
            mallopt(M_MMAP_THRESHOLD, DYNAMIC_MMAP_CEILING)
