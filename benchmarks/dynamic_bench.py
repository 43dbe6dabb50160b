"""Dynamic-scene benchmark: what the uncertainty buys, per synthetic sequence.

    python benchmarks/dynamic_bench.py [--frames 300] [--size 640x480] [--seeds 1 2 3] [--set KEY=VALUE ...]

One row per sequence (3 dynamic seeds and a static control): ATE with and
without uncertainty and their ratio, the uncertainty AUROC against the
ground-truth dynamic masks over all keyframes, the share of ground-truth
dynamic pixels in the static point cloud, and frames/s for both runs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import print_table, run_case_subprocess, track_source  # noqa: E402


def keyframe_masks(cfg, scene, kf_index: np.ndarray, target_area: int) -> np.ndarray:
    """Ground-truth dynamic masks of the keyframes on the BA grid."""
    import cv2

    from droidw_cli.geometry.camera import BA_SCALE
    from droidw_cli.io.prepare import FramePreparer

    prep = FramePreparer((cfg.height, cfg.width), None, target_area)
    h, w = prep.size[0] // BA_SCALE, prep.size[1] // BA_SCALE
    out = np.zeros((len(kf_index), h, w), dtype=bool)
    for n, k in enumerate(kf_index):
        m = scene.frame(int(k)).mask.astype(np.uint8) * 255
        work = prep.image(np.repeat(m[..., None], 3, axis=2))[..., 0].astype(np.float32) / 255.0
        out[n] = cv2.resize(work, (w, h), interpolation=cv2.INTER_AREA) >= 0.5
    return out


def one(args: argparse.Namespace) -> None:
    from droidw_cli.config import load_config
    from droidw_cli.eval import evaluate_ate
    from droidw_cli.eval.dynamic import auroc
    from droidw_cli.export.pointcloud import CloudParams, build_cloud
    from droidw_cli.export.run_files import keyframe_arrays
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import SynthConfig, build_scene
    from droidw_cli.synth.source import SynthSource

    w, h = (int(v) for v in args.size.split("x"))
    cfg = SynthConfig.preset(args.preset, width=w, height=h, frames=args.frames, seed=args.seed)
    scene = build_scene(cfg)
    gt = Trajectory(np.array([cfg.timestamp(k) for k in range(cfg.frames)]),
                    np.asarray(scene.pose(np.arange(cfg.frames)), dtype=np.float64))
    source = SynthSource(cfg)
    overrides = list(args.set) + ([] if args.uncertainty else ["uncertainty.enable=false"])
    result, seconds = track_source(source, source.intrinsics_hint, overrides)
    out = {"ate_cm": evaluate_ate(gt, Trajectory(result.timestamps, result.poses_c2w)).rmse * 100,
           "fps": len(result.timestamps) / seconds, "keyframes": int(len(result.kf_index))}
    if args.uncertainty and result.kf_uncertainty is not None:
        target_area = load_config("default", list(args.set)).io.target_area
        masks = keyframe_masks(cfg, scene, result.kf_index, target_area)
        out["auroc"] = auroc(result.kf_uncertainty, masks) if masks.any() else float("nan")
        cloud = build_cloud(keyframe_arrays(result), CloudParams())
        dyn = masks.reshape(-1)
        out["static_points"] = int(cloud.static.sum())
        out["static_dynamic_share"] = float((cloud.static & dyn).sum() / max(1, cloud.static.sum()))
    print(json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--preset", default="dynamic", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--uncertainty", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(args)
        return
    common = ["--size", args.size, "--frames", str(args.frames)] + [x for s in args.set for x in ("--set", s)]
    cases = [("dynamic", s) for s in args.seeds] + [("static", args.seeds[0])]
    rows, ratios, ate_on, ate_off = [], [], [], []
    for preset, seed in cases:
        on = run_case_subprocess("dynamic_bench.py", ["--preset", preset, "--seed", str(seed), *common])
        off = run_case_subprocess("dynamic_bench.py", ["--preset", preset, "--seed", str(seed), "--uncertainty", "0",
                                                       *common])
        ratio = off["ate_cm"] / max(on["ate_cm"], 1e-9)
        if preset == "dynamic":
            ratios.append(ratio)
            ate_on.append(on["ate_cm"])
            ate_off.append(off["ate_cm"])
        rows.append([f"{preset} seed {seed}", f"{on['ate_cm']:.2f}", f"{off['ate_cm']:.2f}", f"{ratio:.2f}",
                     f"{on.get('auroc', float('nan')):.3f}", f"{100 * on.get('static_dynamic_share', 0.0):.2f}",
                     f"{on['fps']:.2f}", f"{off['fps']:.2f}"])
    print(f"\nDynamic scenes, {args.size}, {args.frames} frames")
    print_table(["sequence", "ATE on [cm]", "ATE off [cm]", "off/on", "AUROC", "dynamic in static PLY [%]",
                 "frames/s on", "frames/s off"], rows)
    if ratios:
        print(f"dynamic sequences: mean ATE on {np.mean(ate_on):.2f} cm, off {np.mean(ate_off):.2f} cm, "
              f"ratio of the means {np.mean(ate_off) / max(np.mean(ate_on), 1e-9):.2f}, "
              f"mean of the ratios {np.mean(ratios):.2f}")


if __name__ == "__main__":
    main()
