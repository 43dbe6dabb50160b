"""Tracking benchmark: ATE, keyframe ratio, frames/s, ms per frame by stage and peak memory.

    python benchmarks/track_bench.py [--presets walk walk-static wobble rotate stopgo fixed forward ride drive
                                      follow follow-static follow-pan] [--seeds 1]
                                     [--frames 0] [--config default] [--baseline] [--backend auto]
                                     [--memory-minutes 0.5 1] [--set KEY=VALUE ...]
    python benchmarks/track_bench.py --presets --memory-minutes 1 10     # memory only

Table 1: one row per synthetic sequence (the generator's realistic presets:
hand-held walk with movers, its static control, a near-still wobbling
camera with people close in front, fast roll/pitch/yaw, stop-and-go, a fixed
camera, and three cameras travelling down a street: a forward walk, a bike
ride and a car drive at 10 frames/s, 1241×376 as on KITTI; two follow shots
in the street, the camera panning to keep one walker in the middle (``follow-static``: the same path with
nobody in the street); motion blur,
JPEG, noise and gain drift as each preset sets them), known calibration,
640×480 unless the preset says otherwise.  "ATE [% path]" is the ATE over
the length of the true path; "heading" the angle between the true and the
estimated direction of travel over the first five keyframes, in the first
camera's frame (:func:`droidw_cli.eval.metrics.heading_error`).  Each sequence is rendered once into
``benchmarks/.cache`` (a TUM-style folder of PNGs) and tracked from there,
so "decode" is real PNG decoding, not rendering.  ``--frames 0`` keeps each preset's own length
(450; 300 for ``fixed``, 240 for ``ride``, 100 for ``drive``).  ``--baseline`` adds the ATE with
``uncertainty.enable=false``.  "ATE kf" is over keyframes only.
Table 2: peak memory against video length (frames streamed from the
generator, nothing on disk, so its frames/s include rendering) and the ATE over the whole stream: the
handheld path sways back and forth, so a long stream revisits its places long after they left the
global BA's horizon, and drift shows there.  Every row runs in its own process.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, peak_mb, print_table, run_case_subprocess, track_source  # noqa: E402

STAGES = ("decode", "motion_filter", "features", "flow", "ba", "global_ba", "filler")
PRESETS = ("walk", "walk-static", "wobble", "rotate", "stopgo", "fixed", "forward", "ride", "drive", "follow",
           "follow-static", "follow-pan")
HEADING_KEYFRAMES = 5  # the initial heading is measured over the first five keyframes


def one(args: argparse.Namespace) -> None:
    """Run one case and print a JSON line (internal: called in a subprocess)."""
    import numpy as np

    from droidw_cli.eval import evaluate_ate
    from droidw_cli.eval.metrics import heading_error
    from droidw_cli.io.calibration import Calibration
    from droidw_cli.io.input import open_source
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import SynthConfig
    from droidw_cli.synth.source import SynthSource

    over = {"seed": args.seed, "apart": args.apart} | ({"frames": args.frames} if args.frames else {})
    cfg = SynthConfig.preset(args.preset, **over)
    if args.stream:
        source = SynthSource(cfg)
    else:
        source = open_source(cached_sequence(cfg, args.preset))
    calib = Calibration(*(float(v) for v in cfg.intrinsics))
    result, seconds = track_source(source, calib, list(args.set), args.backend, args.config)
    ts, poses = _ground_truth(cfg)
    est = Trajectory(result.timestamps, result.poses_c2w)
    fixed = bool(np.allclose(result.poses_c2w, result.poses_c2w[:1], atol=1e-9))
    still = bool(np.allclose(poses, poses[:1]))  # a fixed camera: ATE is undefined, the answer is "identity"
    ate = evaluate_ate(Trajectory(ts, poses), est) if not (still or fixed) else None
    kf = result.kf_index
    ate_kf = (evaluate_ate(Trajectory(ts[kf], poses[kf]), Trajectory(result.timestamps[kf], result.poses_c2w[kf])).rmse
              if len(kf) >= 3 and not still else float("nan"))
    first = kf[:HEADING_KEYFRAMES]
    heading = (heading_error(poses[first], result.poses_c2w[first])
               if len(first) == HEADING_KEYFRAMES and not (still or fixed) else float("nan"))
    path = float(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum())
    print(json.dumps({"frames": len(result.timestamps), "keyframes": int(len(kf)), "seconds": seconds,
                      "path_m": path, "heading_deg": heading,
                      "fps": len(result.timestamps) / seconds, "stages": result.timings, "peak_mb": peak_mb(),
                      "ate_cm": ate.rmse * 100 if ate is not None else float("nan"), "ate_kf_cm": ate_kf * 100,
                      "identity": fixed, "initialised": result.initialised}))


def _ground_truth(cfg):
    import numpy as np

    from droidw_cli.synth import build_scene

    scene = build_scene(cfg)
    ts = np.array([cfg.timestamp(k) for k in range(cfg.frames)])
    poses = np.asarray(scene.pose(np.arange(cfg.frames)), dtype=np.float64).reshape(cfg.frames, 4, 4)
    return ts, poses


def _cell(v: float, fmt: str = "{:.2f}") -> str:
    return "–" if v != v else fmt.format(v)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", nargs="*", default=list(PRESETS), help="none: only the memory table")
    ap.add_argument("--frames", type=int, default=0, help="0 = each preset's own length")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--config", default="default")
    ap.add_argument("--baseline", action="store_true", help="also run with uncertainty.enable=false")
    ap.add_argument("--backend", default="auto", help="BA backend (default auto, as droidw track: native where it builds)")
    ap.add_argument("--memory-minutes", type=float, nargs="*", default=[])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--apart", action="store_true", help="walkers keep apart (SynthConfig.apart)")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--preset", default="walk", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--stream", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(args)
        return
    common = ["--backend", args.backend, "--config", args.config] + [x for s in args.set for x in ("--set", s)]
    common += ["--apart"] if args.apart else []
    rows = []
    for preset in args.presets:
        for seed in args.seeds:
            case = ["--preset", preset, "--seed", str(seed), "--frames", str(args.frames), *common]
            r = run_case_subprocess("track_bench.py", case)
            off = (run_case_subprocess("track_bench.py", case + ["--set", "uncertainty.enable=false"])["ate_cm"]
                   if args.baseline else float("nan"))
            st, n = r["stages"], r["frames"]
            ate = "identity" if r["identity"] else _cell(r["ate_cm"])
            share = _cell(r["ate_cm"] / r["path_m"], "{:.3f}") if r["path_m"] > 0 and not r["identity"] else "–"
            rows.append([f"{preset} seed {seed}", n, f"{100 * r['keyframes'] / n:.0f} %", f"{r['path_m']:.1f}", ate,
                         share, _cell(r["ate_kf_cm"]), _cell(off), _cell(r["heading_deg"], "{:.1f}"), f"{r['fps']:.2f}",
                         *(f"{1000 * st.get(s, 0.0) / n:.0f}" for s in STAGES), f"{r['peak_mb']:.0f}"])
    if rows:
        print(f"\nTracking, config {args.config}, backend {args.backend}, known calibration (ms are per input frame)")
        print_table(["sequence", "frames", "keyframes", "path [m]", "ATE [cm]", "ATE [% path]", "ATE kf [cm]",
                     "ATE off [cm]", "heading [°]", "frames/s",
                     *[f"{s} ms" for s in STAGES], "peak MB"], rows)
    if args.memory_minutes:
        mem_rows = []
        for minutes in args.memory_minutes:
            frames = int(round(minutes * 60 * 30))
            r = run_case_subprocess("track_bench.py", ["--preset", "walk", "--seed", str(args.seeds[0]),
                                                       "--frames", str(frames), "--stream", *common])
            mem_rows.append([f"{minutes:g} min", frames, r["keyframes"], f"{r['peak_mb']:.0f}", f"{r['fps']:.2f}",
                             _cell(r["ate_cm"])])
        print("\nPeak memory against video length (walk preset, 30 frames/s)")
        print_table(["video", "frames", "keyframes", "peak MB", "frames/s", "ATE [cm]"], mem_rows)


if __name__ == "__main__":
    main()
