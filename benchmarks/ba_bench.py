#!/usr/bin/env python3
"""Speed and memory of the uncertainty-aware BA backends on synthetic windows.

    python benchmarks/ba_bench.py                         # table: K = 8 … 256 and the 25-kf/75-edge window
    python benchmarks/ba_bench.py --keyframes 25 --edges 75 --json
    python benchmarks/ba_bench.py --backend cuda --keyframes 256
    python benchmarks/ba_bench.py --backend native --keyframes 25 --edges 75 --window   # the C++ backend
    python benchmarks/ba_bench.py --against /path/to/other/checkout --rounds 5   # old vs new, interleaved

Per configuration it reports the median wall time of ``ba_step`` and of
``uncertainty_step`` (after two warm-up runs; every timed call gets fresh pose
and θ tensors, so no call reuses what an earlier one computed, except the
features' float32 channels-last table, which a tracker window also builds
once) and the peak extra memory of the steps (warm-up included).  With
``--window`` it also times one ``run_window`` iteration with the tracker's
settings (evidence maps, uncertainty step and GN step on one state).  CPU memory is the process's peak resident set size
(``VmHWM`` in /proc/self/status, reset through /proc/self/clear_refs once the
problem is built) minus the resident size at that point; tracemalloc cannot see torch's allocations.  On
CUDA it is ``torch.cuda.max_memory_allocated`` minus the allocation before
the loop.  The table runs every configuration in a fresh subprocess so that
the peaks do not mix.  Edges connect keyframes up to 2 apart in both
directions (about 4 per keyframe), features have 64 channels like XFeat.

``--against DIR`` compares with another checkout of droidw (its ``src`` and
``backends/cpu`` are put first on PYTHONPATH of the baseline's subprocesses):
for every configuration the two run alternately, ``--rounds`` times each, so
that both see the same load on a shared machine; the table then has a
``base`` row (the other checkout) and a row for this checkout, each the median
over the rounds of the per-round medians, and the speed-up of each step.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

TABLE = ((8, None), (16, None), (25, None), (25, 75), (64, None), (128, None), (256, None))
CHANNELS = 64
RADIUS = 2


def _status_kb(key: str) -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1])
    return 0


def _reset_peak() -> None:
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:  # not Linux, or not permitted: the peak then includes set-up
        pass


def measure_window(backend, prob, reps: int, iters: int = 5) -> float | None:
    """Median ms of one ``run_window`` iteration (evidence maps, uncertainty step, GN step).

    Tracker settings (configs/default.yaml): relative mode, bidirectional
    weighting, geo_sigma 1, evidence channels, past the warm-up; float16
    features in a keyframe buffer, as the tracker keeps them.  Each repetition is
    a fresh window of ``iters`` iterations (so it includes the per-window set-up).
    None when the SLAM modules cannot be used this way.
    """
    import numpy as np
    import torch

    from droidw_cli.ba.params import BAParams, UncertaintyParams
    from droidw_cli.ba.synthetic import perturb

    try:
        from droidw_cli.slam.keyframes import KeyframeBuffer
        from droidw_cli.slam.optimizer import SharedState, run_window
    except ImportError:
        return None
    params = BAParams(uncertainty=UncertaintyParams(mode="relative", bidirectional=True, geo_sigma=1.0,
                                                    evidence=True, lr=0.01))
    start = perturb(prob.truth, fixed=1, seed=1)
    n, c, h, w = start.features.shape
    dev = backend.device
    on_device = {"device": dev} if dev.type != "cpu" else {}  # (a baseline checkout may predate the argument)
    edges = prob.edges.to(dev)
    thumbnail = np.zeros((h, w, 3), np.uint8)  # the buffer keeps a JPEG thumbnail of every keyframe
    times = []
    for _ in range(reps + 1):
        buf = KeyframeBuffer((h, w), feature_channels=c, **on_device)
        for t in range(n):
            buf.append(t, float(t), start.poses[t], start.disps[t], thumbnail, start.features[t])
        theta = 0.01 * torch.randn(c + 3, generator=torch.Generator().manual_seed(0))
        shared = SharedState(intrinsics=start.intrinsics.to(dev), theta=theta.to(dev), iterations=100)
        if dev.type == "cuda":
            torch.cuda.synchronize()
        t0 = time.perf_counter()
        run_window(backend, buf, 0, n, edges, params, shared, iters, 1)
        if dev.type == "cuda":
            torch.cuda.synchronize()
        times.append((time.perf_counter() - t0) / iters)
    return 1e3 * statistics.median(times[1:])


def measure(backend_name: str, keyframes: int, edges: int | None, grid: tuple[int, int], reps: int,
            threads: int | None, with_window: bool = False) -> dict:
    import torch

    from droidw_cli.ba.params import BAParams
    from droidw_cli.ba.registry import get_backend
    from droidw_cli.ba.synthetic import make_problem, perturb

    from droidw_cli.runtime.threads import torch_threads

    torch.set_num_threads(threads or torch_threads(0))  # default: the tracker's count (cores − 1 on a small machine)
    backend = get_backend(backend_name)
    h, w = grid
    prob = make_problem(keyframes, h=h, w=w, radius=RADIUS, max_edges=edges, channels=CHANNELS, seed=0)
    state = perturb(prob.truth, fixed=1, seed=1).with_(theta=torch.full((CHANNELS + 1,), 0.01))
    state, edges_set = state.to(backend.device), prob.edges.to(backend.device)
    params = BAParams()
    cuda = backend.device.type == "cuda"

    def sync():
        if cuda:
            torch.cuda.synchronize()

    if cuda:
        backend.ba_step(state, edges_set, params)  # builds / loads the kernels
        sync()
        torch.cuda.reset_peak_memory_stats()
        base = torch.cuda.memory_allocated()
    else:
        _reset_peak()
        base = _status_kb("VmRSS") * 1024
    for _ in range(2):  # warm-up (caches), included in the peak
        backend.ba_step(state, edges_set, params)
        backend.uncertainty_step(state, edges_set, params)
    sync()
    times_ba, times_unc = [], []
    for r in range(reps):
        # fresh poses and θ for every call: nothing one call computed is reused by the next
        fresh = [state.with_(poses=state.poses.clone(), theta=state.theta * (1.0 + 1e-6 * (2 * r + k)))
                 for k in range(2)]
        sync()
        t = time.perf_counter()
        backend.ba_step(fresh[0], edges_set, params)
        sync()
        times_ba.append(time.perf_counter() - t)
        t = time.perf_counter()
        backend.uncertainty_step(fresh[1], edges_set, params)
        sync()
        times_unc.append(time.perf_counter() - t)
    peak = (torch.cuda.max_memory_allocated() if cuda else _status_kb("VmHWM") * 1024) - base
    window = measure_window(backend, prob, reps) if with_window else None
    return {
        "backend": backend.name, "keyframes": keyframes, "edges": edges_set.num_edges, "grid": f"{h}x{w}",
        "threads": torch.get_num_threads(), "ms_ba_step": 1e3 * statistics.median(times_ba),
        "ms_uncertainty_step": 1e3 * statistics.median(times_unc), "peak_mb": max(peak, 0) / 2**20,
        "ms_window_iter": window,
    }


def _row(r: dict) -> str:
    line = (f"{r['backend']:>5} {r['keyframes']:>5} {r['edges']:>6} {r['grid']:>6} {r['ms_ba_step']:>10.1f} "
            f"{r['ms_uncertainty_step']:>10.1f} {r['peak_mb']:>9.0f}")
    if r.get("ms_window_iter") is not None:
        line += f"   run_window iteration {r['ms_window_iter']:.1f} ms"
    return line


def _run_child(args, k: int, e: int | None, src_root: str | None = None) -> dict:
    """One configuration in a fresh subprocess (this checkout, or ``src_root``'s code)."""
    cmd = [sys.executable, __file__, "--backend", args.backend, "--keyframes", str(k), "--grid", args.grid,
           "--reps", str(args.reps), "--json"] + (["--edges", str(e)] if e else []) + \
          (["--threads", str(args.threads)] if args.threads else []) + (["--window"] if args.window else [])
    env = None
    if src_root is not None:
        root = Path(src_root).resolve()
        paths = [str(root / "src"), str(root / "backends" / "cpu")] + [os.environ.get("PYTHONPATH", "")]
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(paths).rstrip(os.pathsep))
    out = subprocess.run(cmd, capture_output=True, text=True, check=True, env=env).stdout.strip().splitlines()[-1]
    return json.loads(out)


def _median_row(runs: list[dict]) -> dict:
    row = dict(runs[0])
    for key in ("ms_ba_step", "ms_uncertainty_step", "peak_mb", "ms_window_iter"):
        vals = [r[key] for r in runs if r.get(key) is not None]
        row[key] = statistics.median(vals) if vals else None
    return row


def _compare(args, configs, header: str) -> list[dict]:
    """Interleaved rounds of the baseline checkout and this one; prints both rows and the speed-ups."""
    print(header)
    rows = []
    for k, e in configs:
        base, mine = [], []
        for _ in range(args.rounds):
            base.append(_run_child(args, k, e, args.against))
            mine.append(_run_child(args, k, e))
        b, m = _median_row(base), _median_row(mine)
        b["backend"] = "base"
        print(_row(b))
        gain = (f"   x{b['ms_ba_step'] / m['ms_ba_step']:.1f} ba, "
                f"x{b['ms_uncertainty_step'] / m['ms_uncertainty_step']:.1f} unc")
        if b.get("ms_window_iter") and m.get("ms_window_iter"):
            gain += f", x{b['ms_window_iter'] / m['ms_window_iter']:.1f} run_window"
        print(_row(m) + gain, flush=True)
        rows += [b, m]
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--backend", default="cpu", help="cpu | native | cuda | auto (default cpu)")
    ap.add_argument("--keyframes", type=int, help="keyframes in the window (omit for the whole table)")
    ap.add_argument("--edges", type=int, help="cap on the number of edges (default: all pairs up to 2 apart)")
    ap.add_argument("--grid", default="48x64", help="BA grid HxW (default 48x64)")
    ap.add_argument("--reps", type=int, default=5, help="measured repetitions (median reported)")
    ap.add_argument("--threads", type=int, help="torch intra-op threads (default: the tracker's, see `threads`)")
    ap.add_argument("--against", metavar="DIR", help="compare with the droidw checkout in DIR (interleaved runs)")
    ap.add_argument("--rounds", type=int, default=3, help="with --against: alternating runs per side (default 3)")
    ap.add_argument("--window", action="store_true",
                    help="also time one run_window iteration with the tracker's settings (evidence included)")
    ap.add_argument("--json", action="store_true", help="last line: one JSON object")
    args = ap.parse_args(argv)
    h, w = (int(v) for v in args.grid.lower().split("x"))
    header = f"{'back':>5} {'kf':>5} {'edges':>6} {'grid':>6} {'ba ms':>10} {'unc ms':>10} {'peak MB':>9}"
    if args.against:
        configs = [(args.keyframes, args.edges)] if args.keyframes is not None else list(TABLE)
        rows = _compare(args, configs, header)
        if args.json:
            print(json.dumps(rows))
        return 0
    if args.keyframes is not None:
        r = measure(args.backend, args.keyframes, args.edges, (h, w), args.reps, args.threads, args.window)
        if args.json:
            print(json.dumps(r))
        else:
            print(header)
            print(_row(r))
        return 0
    print(header)
    rows = []
    for k, e in TABLE:
        rows.append(_run_child(args, k, e))
        print(_row(rows[-1]), flush=True)
    if args.json:
        print(json.dumps(rows[-1]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
