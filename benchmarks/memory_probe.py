"""Memory probe: what the tracker holds per keyframe, sampled while it runs.

    python benchmarks/memory_probe.py [--minutes 1] [--every 100] [--preset walk] [--seed 1]

Streams a synthetic preset (as ``track_bench.py --memory-minutes`` does) and,
every ``--every`` new keyframes, prints the resident set size (RSS; with
``--trim`` also RSS after ``malloc_trim``, what the heap could hand back: the
rest is live or fragmented; trimming changes the later peaks), the peak RSS
so far, malloc's own count (``mallinfo2``: MB in live heap blocks, in free heap
chunks, in blocks mapped on their own), and the bytes held by each long-lived
structure of the run: the keyframe buffer, the frontend's images, edge cache
and dynamic masks, the backend's JPEG images and the filler's per-frame
records.  At the end it prints the same after the final global BA and after
the result is built, and the result's arrays.  torch allocations are invisible
to tracemalloc, hence the explicit accounting.
"""

from __future__ import annotations

import argparse
import ctypes
import resource
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import track_source  # noqa: E402


def rss_mb(trim: bool = False) -> float:
    if trim:
        from droidw_cli.runtime.heap import release_free_memory

        release_free_memory()
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20


class _MallInfo2(ctypes.Structure):
    """glibc's ``struct mallinfo2`` (glibc 2.33+), summed over every arena."""

    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]


def heap_mb() -> str:
    """malloc's view as 'in use/free/mapped' MB: live heap blocks, free heap bytes (holes), mmapped blocks."""
    try:
        fn = ctypes.CDLL("libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return "-"
    fn.restype = _MallInfo2
    m = fn()
    return f"{m.uordblks / 2**20:.0f}/{m.fordblks / 2**20:.0f}/{m.hblkhd / 2**20:.0f}"


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def hwm_mb(reset: bool = False) -> float:
    """Peak RSS since the last reset (VmHWM); ``reset`` starts a new window (clear_refs 5)."""
    with open("/proc/self/status") as f:
        value = next(int(line.split()[1]) for line in f if line.startswith("VmHWM")) / 1024.0
    if reset:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    return value


def nbytes(x) -> int:
    """Bytes of the arrays/tensors/bytes inside x (containers walked; shared storage not deduplicated)."""
    if x is None:
        return 0
    if isinstance(x, torch.Tensor):
        return x.element_size() * x.nelement()
    if isinstance(x, np.ndarray):
        return x.nbytes
    if isinstance(x, (bytes, bytearray)):
        return len(x)
    if isinstance(x, dict):
        return sum(nbytes(v) for v in x.values())
    if isinstance(x, (list, tuple)):
        return sum(nbytes(v) for v in x)
    if hasattr(x, "__dict__"):
        return sum(nbytes(v) for v in vars(x).values())
    return 0


def account(fe, gba, filler) -> dict[str, int]:
    buf, m = fe.buffer, fe.masks
    return {
        "buf.poses+disps+prior": nbytes([buf.poses, buf.disps, buf.depth_prior]),
        "buf.features": buf._feature_slab.nbytes if buf._feature_slab is not None else 0,  # the slab, free rows too
        "buf.frozen_u+conf": nbytes([buf.frozen_u, buf.frozen_conf]),
        "buf.thumbnails": nbytes(buf.thumbnails),
        "fe.images": nbytes(fe.images),
        "fe.cache": fe.cache.nbytes,
        "fe._raw+_epipolar": nbytes([fe._raw, fe._epipolar]),
        "masks": nbytes([m.images, m.masks, m.current]),
        "masks.edges": nbytes(getattr(m, "edges", None)),
        "masks.final+matches": nbytes([getattr(m, "final", None), getattr(m, "matches", None)]),
        "gba.images": gba.images.nbytes,
        "filler.pending": nbytes(filler._pending),
        "filler.relative": getattr(filler._relative, "nbytes", None) or nbytes(filler._relative),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--minutes", type=float, default=1.0)
    ap.add_argument("--every", type=int, default=100)
    ap.add_argument("--preset", default="walk")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--trim", action="store_true", help="also print RSS after malloc_trim(0)")
    args = ap.parse_args()

    from droidw_cli.io.calibration import Calibration
    from droidw_cli.slam import tracker as tracker_mod
    from droidw_cli.synth import SynthConfig
    from droidw_cli.synth.source import SynthSource

    frames = int(round(args.minutes * 60 * 30))
    cfg = SynthConfig.preset(args.preset, seed=args.seed, frames=frames)
    seen = {"kf": 0, "t0": time.perf_counter()}
    keys: list[str] = []

    def report(tag: str, fe, gba, filler) -> None:
        acc = account(fe, gba, filler)
        if not keys:
            keys.extend(acc)
            print("tag kf frames_filled rss trimmed peak heap(used/free/mapped) " + " ".join(keys) + " total (all MB)",
                  flush=True)
        tot = sum(acc.values())
        cells = " ".join(f"{v / 2**20:.1f}" for v in acc.values())
        trimmed = f"{rss_mb(True):.0f}" if args.trim else "-"
        print(f"{tag} {len(fe.buffer)} {len(filler._relative)} {rss_mb():.0f} {trimmed} {peak_mb():.0f} {heap_mb()} "
              f"{cells} {tot / 2**20:.1f}  [{time.perf_counter() - seen['t0']:.0f} s]", flush=True)

    original_gba = tracker_mod.GlobalBackend

    class ProbedBackend(original_gba):
        filler = None

        def keyframe_added(self, k, image):
            super().keyframe_added(k, image)
            seen["kf"] += 1
            if seen["kf"] % args.every == 0:
                report(f"kf{seen['kf']}", self.fe, self, ProbedBackend.filler)

        def run(self, iters):
            # which stretch set each new peak: the tracking since the last global BA, or a global BA itself
            before = hwm_mb(reset=True)
            edges_before = len(self.fe.cache)
            out = super().run(iters)
            during = hwm_mb(reset=True)
            for what, value in (("tracking", before), ("global BA", during)):
                if value > seen.get("max", 0.0):
                    seen["max"] = value
                    print(f"new peak {value:.0f} MB in {what} at keyframe {len(self.fe.buffer)} "
                          f"(edges {edges_before} -> {len(self.fe.cache)}, problem from {self.lo}; after it rss "
                          f"{rss_mb():.0f} MB, heap {heap_mb()})", flush=True)
            return out

        def finish(self):
            report("before_final", self.fe, self, ProbedBackend.filler)
            phase("first pass (peak columns above: since the start)")
            out = super().finish()
            phase("final global BA")
            report("after_final", self.fe, self, ProbedBackend.filler)
            return out

    original_filler = tracker_mod.TrajectoryFiller

    class ProbedFiller(original_filler):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            ProbedBackend.filler = self

        def finish(self):
            phase("uncertainty + confidence")
            out = super().finish()
            phase("filler.finish")
            return out

    peaks: list[float] = []

    def phase(name: str) -> None:
        peaks.append(hwm_mb(reset=True))
        print(f"phase {name}: peak {peaks[-1]:.0f} MB, rss now {rss_mb():.0f} MB", flush=True)

    original_dyn = tracker_mod._dynamic_record

    def probed_dyn(*a, **kw):
        out = original_dyn(*a, **kw)
        phase("dynamics")
        return out

    tracker_mod._dynamic_record = probed_dyn

    tracker_mod.GlobalBackend = ProbedBackend
    tracker_mod.TrajectoryFiller = ProbedFiller
    calib = Calibration(*(float(v) for v in cfg.intrinsics))
    hwm_mb(reset=True)
    result, seconds = track_source(SynthSource(cfg), calib, list(args.set))
    phase("result")
    arrays = {k: v.nbytes for k, v in vars(result).items() if isinstance(v, np.ndarray)}
    print(f"result: frames {len(result.timestamps)} keyframes {len(result.kf_index)} {seconds:.0f} s "
          f"rss {rss_mb():.0f} MB; peak of the whole run {max(peaks):.0f} MB")
    print("result arrays MB: " + " ".join(f"{k}={v / 2**20:.1f}" for k, v in arrays.items() if v > 2**16))


if __name__ == "__main__":
    main()
