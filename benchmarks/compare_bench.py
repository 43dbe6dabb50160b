"""Side by side: another revision of droidw against this working tree, on the same sequences, in one run.

    python benchmarks/compare_bench.py --base d9c6d11 --presets walk walk-static wobble rotate stopgo --seeds 1
    python benchmarks/compare_bench.py --base d9c6d11 --presets forward ride drive --seeds 1 2 3 --rounds 1
    python benchmarks/compare_bench.py --base d9c6d11 --config fast --presets rotate

Each sequence is rendered once by this tree's generator into ``benchmarks/.cache`` (as ``track_bench.py`` does)
and tracked with ``droidw track FOLDER --quiet`` twice per round: by the base revision, checked out (detached) in
a git worktree under ``benchmarks/.cache/revisions/REV`` and run with its ``src`` and ``backends/cpu`` first on
``PYTHONPATH``, and by this tree, alternately, so both see the same load on a shared machine.  Each side runs
with its own default backend choice unless ``--base-backend`` / ``--backend`` say otherwise (the base, which
does not know this tree's newer backends, gets ``cpu`` by default).  Both trajectories are evaluated by this
tree's evaluator against the generator's ground truth (ATE RMSE after Sim(3) alignment); frames/s is the
run's own figure from its ``run.json`` (frames over the tracking wall time, start-up excluded).  With several
rounds, the table gives medians; ratios are new / base, so a speed-up reads > 1 and an accuracy gain < 1.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from _bench_common import HERE, cached_sequence, print_table

ROOT = HERE.parent


def base_checkout(rev: str) -> Path:
    """A detached worktree of ``rev`` under ``benchmarks/.cache/revisions`` (made on first use)."""
    sha = subprocess.run(["git", "rev-parse", "--verify", f"{rev}^{{commit}}"], cwd=ROOT, capture_output=True,
                         text=True)
    if sha.returncode != 0:
        raise SystemExit(f"compare_bench: {rev!r} is not a revision of this repository")
    folder = HERE / ".cache" / "revisions" / sha.stdout.strip()[:12]
    if not (folder / "src" / "droidw_cli").is_dir():
        folder.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["git", "worktree", "add", "--detach", "--force", str(folder), sha.stdout.strip()], cwd=ROOT,
                       check=True, capture_output=True)
    return folder


def track(folder: Path, checkout: Path | None, backend: str | None, config: str, sets: list[str]) -> dict:
    """``droidw track folder`` by ``checkout``'s code (None: this tree's); its run.json and trajectory."""
    env = dict(os.environ)
    if checkout is not None:
        paths = [str(checkout / "src"), str(checkout / "backends" / "cpu"), env.get("PYTHONPATH", "")]
        env["PYTHONPATH"] = os.pathsep.join(p for p in paths if p)
    with tempfile.TemporaryDirectory(prefix="compare-") as tmp:
        out = Path(tmp) / "run"
        cmd = [sys.executable, "-m", "droidw_cli", "track", str(folder), "--out", str(out), "--quiet",
               "--config", config] + (["--backend", backend] if backend else []) + \
              [x for s in sets for x in ("--set", s)]
        proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=tmp)
        if proc.returncode != 0:
            side = "base" if checkout is not None else "this tree"
            raise SystemExit(f"compare_bench: {side} failed on {folder.name}:\n{proc.stderr[-2000:]}")
        from droidw_cli.io.trajectory import read_tum

        return {"run": json.loads((out / "run.json").read_text()), "traj": read_tum(out / "traj.txt")}


def ate_cm(est, cfg) -> float:
    """ATE RMSE (cm, Sim(3)) of a trajectory against the generator's ground truth; nan for a fixed camera."""
    import numpy as np

    from droidw_cli.eval import evaluate_ate
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import build_scene

    poses = np.asarray(build_scene(cfg).pose(np.arange(cfg.frames)), dtype=np.float64).reshape(cfg.frames, 4, 4)
    if np.allclose(poses, poses[:1]):
        return float("nan")
    ts = np.array([cfg.timestamp(k) for k in range(cfg.frames)])
    return evaluate_ate(Trajectory(ts, poses), est).rmse * 100


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="the revision to compare with (a commit, tag or branch)")
    ap.add_argument("--presets", nargs="+", default=["walk", "walk-static", "wobble", "rotate", "stopgo"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--frames", type=int, default=0, help="0 = each preset's own length")
    ap.add_argument("--rounds", type=int, default=1, help="alternating runs per side (medians are shown)")
    ap.add_argument("--config", default="default")
    ap.add_argument("--backend", default=None, help="this tree's backend (default: its own choice)")
    ap.add_argument("--base-backend", default="cpu", help="the base's backend (default: cpu)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="for this tree only")
    args = ap.parse_args()

    from droidw_cli.synth import SynthConfig

    checkout = base_checkout(args.base)
    rows = []
    for preset in args.presets:
        for seed in args.seeds:
            cfg = SynthConfig.preset(preset, seed=seed, **({"frames": args.frames} if args.frames else {}))
            folder = cached_sequence(cfg, preset)
            base, new = [], []
            for _ in range(args.rounds):
                base.append(track(folder, checkout, args.base_backend, args.config, []))
                new.append(track(folder, None, args.backend, args.config, args.set))
            b_ate = statistics.median(ate_cm(r["traj"], cfg) for r in base)
            n_ate = statistics.median(ate_cm(r["traj"], cfg) for r in new)
            b_fps = statistics.median(r["run"]["fps"] for r in base)
            n_fps = statistics.median(r["run"]["fps"] for r in new)
            still = b_ate != b_ate
            rows.append([f"{preset} seed {seed}", "identity" if still else f"{b_ate:.2f}",
                         "identity" if still else f"{n_ate:.2f}", "–" if still else f"{n_ate / b_ate:.2f}",
                         f"{b_fps:.2f}", f"{n_fps:.2f}", f"{n_fps / b_fps:.2f}",
                         new[-1]["run"].get("backend", "?")])
            print(f"{preset} seed {seed}: ATE {rows[-1][1]} → {rows[-1][2]} cm, {b_fps:.2f} → {n_fps:.2f} frames/s",
                  file=sys.stderr, flush=True)
    print(f"\n{args.base} (backend {args.base_backend}) against this tree, config {args.config}, "
          f"{args.rounds} round(s), medians; ratios new / base")
    print_table(["sequence", "ATE base [cm]", "ATE new [cm]", "ATE ratio", "frames/s base", "frames/s new",
                 "speed-up", "backend new"], rows)


if __name__ == "__main__":
    main()
