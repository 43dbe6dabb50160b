"""The heap's free pages go back to the OS around each global BA, its large blocks are mapped, its arenas capped (runtime/heap.py)."""

from __future__ import annotations

import ctypes.util
import os
import subprocess
import sys

import pytest

from droidw_cli.runtime.heap import release_free_memory

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
from droidw_cli.runtime.heap import large_blocks_mapped


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


#: six threads that each allocate: glibc gives each a new arena of its own up to the cap
_ARENAS = """
import ctypes, sys, threading
from droidw_cli.runtime.heap import limit_arenas

applied = limit_arenas(2) if sys.argv[1] == "cap" else None
barrier = threading.Barrier(6)
held = []

def work():
    held.append(bytearray(200_000))
    barrier.wait()

threads = [threading.Thread(target=work) for _ in range(6)]
for t in threads:
    t.start()
for t in threads:
    t.join()
sys.stderr.flush()
ctypes.CDLL("libc.so.6").malloc_stats()  # one "Arena N:" block per arena, on stderr
print(applied)
"""


def _arenas(mode: str, arena_max: str | None = None) -> tuple[str, int]:
    """(what limit_arenas returned, arenas made) in a fresh interpreter; MALLOC_ARENA_MAX only as given."""
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}
    if arena_max is not None:
        env["MALLOC_ARENA_MAX"] = arena_max
    proc = subprocess.run([sys.executable, "-c", _ARENAS, mode], capture_output=True, text=True, check=True, env=env)
    return proc.stdout.strip(), proc.stderr.count("Arena ")


@glibc
def test_arenas_are_capped_at_two():
    """Uncapped, six allocating threads make more than two arenas; capped, two; MALLOC_ARENA_MAX wins."""
    assert _arenas("free")[1] > 2
    assert _arenas("cap") == ("True", 2)
    applied, count = _arenas("cap", arena_max="3")
    assert applied == "False" and count <= 3
