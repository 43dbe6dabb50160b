"""The heap's free pages go back to the OS before each global BA (slam/heap.py)."""

from __future__ import annotations

import ctypes.util
import sys

import pytest

from droidw_cli.slam.heap import release_free_memory


def _rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


@pytest.mark.skipif(not sys.platform.startswith("linux") or not ctypes.util.find_library("c"),
                    reason="glibc's malloc_trim")
def test_freed_holes_are_returned():
    """Blocks under the mmap threshold, every other one freed: holes that only a trim gives back."""
    blocks = [bytearray(64 * 1024) for _ in range(4000)]  # 250 MB, touched
    del blocks[::2]
    before = _rss_mb()
    assert release_free_memory()
    assert before - _rss_mb() > 60  # about 125 MB of holes
    del blocks
