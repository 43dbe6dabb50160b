"""Tracking benchmark: frames/s, seconds per stage, peak memory and ATE on synthetic sequences.

    python benchmarks/track_bench.py [--frames 300] [--size 640x480] [--seeds 1 2] [--backend cpu]
                                     [--memory-minutes 0.5 1] [--set KEY=VALUE ...]

Table 1: one row per sequence (static and dynamic presets, uncertainty on).
Table 2: peak memory against video length (frames streamed from the
generator, nothing on disk).  Every row runs in its own process.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import peak_mb, print_table, run_case_subprocess, track_source  # noqa: E402

STAGES = ("decode", "motion_filter", "features", "flow", "ba", "global_ba", "filler")


def one(args: argparse.Namespace) -> None:
    """Run one case and print a JSON line (internal: called in a subprocess)."""
    from droidw_cli.eval import evaluate_ate
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import SynthConfig
    from droidw_cli.synth.source import SynthSource

    w, h = (int(v) for v in args.size.split("x"))
    cfg = SynthConfig.preset(args.preset, width=w, height=h, frames=args.frames, seed=args.seed)
    source = SynthSource(cfg)
    result, seconds = track_source(source, source.intrinsics_hint, list(args.set), args.backend)
    gt = Trajectory(*_ground_truth(cfg))
    ate = evaluate_ate(gt, Trajectory(result.timestamps, result.poses_c2w)).rmse
    print(json.dumps({"frames": len(result.timestamps), "keyframes": int(len(result.kf_index)), "seconds": seconds,
                      "fps": len(result.timestamps) / seconds, "stages": result.timings, "peak_mb": peak_mb(),
                      "ate_cm": ate * 100}))


def _ground_truth(cfg):
    import numpy as np

    from droidw_cli.synth import build_scene

    scene = build_scene(cfg)
    ts = np.array([cfg.timestamp(k) for k in range(cfg.frames)])
    poses = np.asarray(scene.pose(np.arange(cfg.frames)), dtype=np.float64).reshape(cfg.frames, 4, 4)
    return ts, poses


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--backend", default="cpu")
    ap.add_argument("--memory-minutes", type=float, nargs="*", default=[0.5, 1.0])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--preset", default="static", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(args)
        return
    common = ["--size", args.size, "--backend", args.backend] + [x for s in args.set for x in ("--set", s)]
    rows = []
    for preset in ("static", "dynamic"):
        for seed in args.seeds:
            r = run_case_subprocess("track_bench.py", ["--preset", preset, "--seed", str(seed), "--frames",
                                                       str(args.frames), *common])
            st = r["stages"]
            rows.append([f"{preset} seed {seed}", r["frames"], r["keyframes"], f"{r['fps']:.2f}",
                         *(f"{st.get(s, 0.0):.1f}" for s in STAGES), f"{r['peak_mb']:.0f}", f"{r['ate_cm']:.2f}"])
    print(f"\nTracking, {args.size}, {args.frames} frames, backend {args.backend}, uncertainty on")
    print_table(["sequence", "frames", "keyframes", "frames/s", *[f"{s} [s]" for s in STAGES], "peak MB", "ATE [cm]"],
                rows)
    if args.memory_minutes:
        mem_rows = []
        for minutes in args.memory_minutes:
            frames = int(round(minutes * 60 * 30))
            r = run_case_subprocess("track_bench.py", ["--preset", "dynamic", "--seed", str(args.seeds[0]),
                                                       "--frames", str(frames), *common])
            mem_rows.append([f"{minutes:g} min", frames, r["keyframes"], f"{r['peak_mb']:.0f}", f"{r['fps']:.2f}"])
        print(f"\nPeak memory against video length ({args.size}, 30 frames/s, dynamic preset)")
        print_table(["video", "frames", "keyframes", "peak MB", "frames/s"], mem_rows)


if __name__ == "__main__":
    main()
