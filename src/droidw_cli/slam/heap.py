"""Hand the heap's free pages back to the operating system before each global BA.

glibc's malloc keeps memory that was freed.  The global BA allocates per-edge
temporaries of tens of MB whose sizes change from run to run, and the holes
they leave are not always reused, so over a long video the resident set at the
global BA's peak creeps upward although what is live stays bounded (the
200-keyframe horizon): on a 10-minute stream the peak rose from 1503 MB at
keyframe 220 to 1793 MB at keyframe 1000 with the same ~1800 edges in the
problem (``benchmarks/memory_probe.py``).  ``malloc_trim(0)`` releases every
free page (the top of each arena and whole free pages inside it), so each run
starts from what is live.  Elsewhere (musl, macOS, Windows) this does nothing.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import sys
from functools import cache


@cache
def _malloc_trim():
    """glibc's malloc_trim, or None where there is no glibc."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        trim = libc.malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Return the heap's free pages to the OS; True when some memory was released."""
    trim = _malloc_trim()
    return bool(trim(0)) if trim is not None else False
