"""The heap's free pages go back to the OS before each global BA, and its large blocks are mapped (slam/heap.py)."""

from __future__ import annotations

import ctypes.util
import subprocess
import sys

import pytest

from droidw_cli.slam.heap import release_free_memory

glibc = pytest.mark.skipif(not sys.platform.startswith("linux") or not ctypes.util.find_library("c"),
                           reason="glibc's malloc_trim and mallopt")


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


@glibc
def test_freed_holes_are_returned():
    """Blocks under the mmap threshold, every other one freed: holes that only a trim gives back."""
    blocks = [bytearray(64 * 1024) for _ in range(4000)]  # 250 MB, touched
    del blocks[::2]
    before = _rss_mb()
    assert release_free_memory()
    assert before - _rss_mb() > 60  # about 125 MB of holes
    del blocks



#: run in a fresh interpreter: a long-lived test process has free heap holes that a 12 MB block may fit,
#: and glibc maps a block only when no free chunk can hold it
_PROBE = """
from droidw_cli.slam.heap import large_blocks_mapped


def anonymous_bytes():
    total = 0
    with open("/proc/self/maps") as f:
        for line in f:
            parts = line.split()
            if len(parts) == 5:  # no path: anonymous ([heap] and [stack] have one)
                lo, hi = (int(v, 16) for v in parts[0].split("-"))
                total += hi - lo
    return total


size = 12 * 2**20
with large_blocks_mapped(8 * 2**20) as applied:
    before = anonymous_bytes()
    inside = bytearray(size)
    grew_inside = anonymous_bytes() - before
    del inside
before = anonymous_bytes()
after = bytearray(size)
print(applied, grew_inside >= size, anonymous_bytes() - before >= size)
"""


@glibc
def test_large_blocks_are_mapped_only_inside_the_block():
    """Inside, a 12 MB block gets a mapping of its own; after it, the heap takes such a block (threshold 32 MB)."""
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "True", "False"]
