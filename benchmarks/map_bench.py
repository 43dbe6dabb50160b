"""Gaussian-map benchmark (issue 56): ``droidw map`` on the generator's hand-held walk.

    python benchmarks/map_bench.py [--seed 1] [--frames 450] [--minutes 8] [--steps 200] [--runs DIR]

Tracks (or, with ``--runs DIR`` holding ``mono/`` and ``rgbd/`` run folders, reuses) the ``walk`` preset at
640×480 (rendered once into ``benchmarks/.cache``), monocular with the default config and RGB-D with
``configs/rgbd.yaml``, then maps

* the monocular run with its dynamic masks (the default),
* the same run without masks (``--no-masks``: the movers are mapped as static and leave ghosts),
* the RGB-D run with its masks,

and prints one table: PSNR / SSIM on the static pixels of the held-out frames (every 20th non-keyframe;
"static pixels" from the generator's ground-truth masks), PSNR on their dynamic pixels for the static map
alone and the composite with the object Gaussians (all held-out frames, and those within 2 frames of a
keyframe), the Gaussian counts and the minutes each map took.  The maps are written under ``--out``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, print_table  # noqa: E402


def _track(sequence: Path, out: Path, depth: bool) -> Path:
    from droidw_cli.track import run_track

    if not (out / "keyframes.npz").exists():
        run_track(sequence, out, backend="cpu", progress=False, echo=lambda *a, **k: None, depth=depth)
    return out


def _cell(v, fmt="{:.2f}") -> str:
    return "–" if v is None or v != v else fmt.format(v)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--frames", type=int, default=450)
    ap.add_argument("--minutes", type=float, default=8.0)
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--runs", type=Path, default=None, help="reuse DIR/mono and DIR/rgbd (tracked if missing)")
    ap.add_argument("--out", type=Path, default=Path("map-bench"))
    ap.add_argument("--cases", nargs="*", default=["masks", "no-masks", "rgbd"])
    args = ap.parse_args()

    import torch

    from droidw_cli.gaussians.build import run_map
    from droidw_cli.gaussians.params import MapParams
    from droidw_cli.synth import SynthConfig

    torch.set_num_threads(2)
    cfg = SynthConfig.preset("walk", seed=args.seed, frames=args.frames)
    sequence = cached_sequence(cfg, "walk")
    runs = args.runs or (Path(__file__).resolve().parent / ".cache" / f"map-runs-walk-seed{args.seed}-{args.frames}")
    rows, docs = [], {}
    for case in args.cases:
        run = _track(sequence, runs / ("rgbd" if case == "rgbd" else "mono"), depth=case == "rgbd")
        params = MapParams(steps=args.steps, minutes=args.minutes, use_masks=case != "no-masks")
        t = time.perf_counter()
        doc = run_map(run, args.out / case, params, input_path=sequence)
        minutes = (time.perf_counter() - t) / 60
        docs[case] = doc
        m = doc["heldout"]["mean"]
        rows.append([case, _cell(m["psnr_static_pixels"]), _cell(m["ssim_static_pixels"], "{:.3f}"),
                     _cell(m["psnr_all"]), _cell(m["psnr_dynamic_static_only"]), _cell(m["psnr_dynamic_composite"]),
                     _cell(m["near_keyframe"]["psnr_dynamic_static_only"]),
                     _cell(m["near_keyframe"]["psnr_dynamic_composite"]),
                     doc["gaussians"]["static"], doc["gaussians"]["dynamic"], doc["static"]["steps"],
                     doc["static"]["ended"], f"{minutes:.1f}"])
        print(json.dumps({"case": case, "mean": m, "seconds": doc["seconds"]}), flush=True)
    print(f"\nwalk seed {args.seed}, {args.frames} frames, 640x480; held-out views every 20th non-keyframe, "
          f"scored at the map's size; --minutes {args.minutes:g} --steps {args.steps}\n")
    print_table(["case", "PSNR static px", "SSIM static px", "PSNR all", "dyn px: static only", "dyn px: composite",
                 "near kf: static", "near kf: composite", "static G", "object G", "steps", "ended", "minutes"], rows)
    if "masks" in docs and "no-masks" in docs:
        a, b = (docs[c]["heldout"]["mean"]["psnr_static_pixels"] for c in ("masks", "no-masks"))
        print(f"\nmasks − no masks on static pixels: {a - b:+.2f} dB (target ≥ +1.5)")
    if "masks" in docs and "rgbd" in docs:
        a, b = (docs[c]["heldout"]["mean"]["psnr_static_pixels"] for c in ("rgbd", "masks"))
        print(f"RGB-D − monocular on static pixels: {a - b:+.2f} dB (target ≥ 0)")


if __name__ == "__main__":
    main()
