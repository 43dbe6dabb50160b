"""``droidw demo``: the main job on a built-in synthetic dynamic scene.

Generates a short sequence with exact ground truth (people walking through a
textured room), tracks it with and without the dynamic uncertainty, and
prints ATE and speed for both, plus the paths of everything written.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import click


def reusable_sequence(folder: Path, cfg) -> bool:
    """True when ``folder`` holds a complete sequence that the generator wrote from exactly ``cfg``.

    The writer puts ``synth.json`` (the SynthConfig) in last and moves the folder into
    place only when it is whole, so a matching ``synth.json`` means the same frames.
    """
    try:
        meta = json.loads((folder / "synth.json").read_text())
    except (OSError, ValueError):
        return False
    return isinstance(meta, dict) and meta.get("config") == json.loads(json.dumps(dataclasses.asdict(cfg)))


@click.command("demo")
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("droidw-demo"), show_default=True)
@click.option("--frames", type=click.IntRange(min=1), default=90, show_default=True,
              help="Length of the generated sequence.")
@click.option("--seed", type=int, default=1, show_default=True)
@click.option("--backend", default="auto", show_default=True)
@click.option("--config", "config_name", default="default", show_default=True,
              help="Tracking config.  (`fast` keeps grid-px thresholds at a 2/3-size grid, so the same camera motion "
                   "reads 2/3 as far: on the demo's 90 frames it makes 2 keyframes and never initialises.)")
@click.option("--no-baseline", is_flag=True, help="Skip the uncertainty-off comparison run.")
@click.option("--overwrite", is_flag=True,
              help="Generate the sequence again even when OUT/sequence holds one made with the same settings.")
@click.option("--quiet", is_flag=True, help="No progress bars.")
def demo(out_dir, frames, seed, backend, config_name, no_baseline, overwrite, quiet):
    """Generate a synthetic dynamic scene, track it, evaluate it.

    \b
    Example:
      droidw demo --out droidw-demo

    Run again, it reuses OUT/sequence when that was generated with the same
    --frames and --seed (else it asks for --overwrite) and replaces the runs.
    A run that never initialises (too short a clip) gets no ATE.
    """
    from droidw_cli.eval import evaluate_ate
    from droidw_cli.io.trajectory import read_trajectory
    from droidw_cli.synth import SynthConfig, write_sequence
    from droidw_cli.track import run_track

    progress = not quiet and sys.stderr.isatty()
    seq = out_dir / "sequence"
    cfg = SynthConfig.preset("dynamic", seed=seed, frames=frames)
    if not overwrite and reusable_sequence(seq, cfg):
        click.echo(f"reusing the synthetic sequence in {seq} (same settings; --overwrite generates it again)")
    else:
        click.echo(f"generating {frames} frames of a synthetic dynamic scene into {seq} ...")
        write_sequence(cfg, seq, video=False, progress=progress, overwrite=overwrite)
    gt = read_trajectory(seq / "groundtruth.txt")
    runs = [("uncertainty on", out_dir / "run", ())]
    if not no_baseline:
        runs.append(("uncertainty off", out_dir / "run-baseline", ("uncertainty.enable=false",)))
    rows = []
    for label, run_dir, overrides in runs:
        click.echo(f"tracking ({label}) ...")
        result, paths = run_track(seq, run_dir, None, backend, config_name, overrides, progress=progress)
        rmse = (evaluate_ate(gt, read_trajectory(run_dir / "traj.txt"), align="sim3").rmse
                if result.initialised else None)  # every pose the first: nothing to align
        rows.append((label, rmse, result.fps, len(result.kf_index), paths))
    click.echo("")
    click.echo(f"{'run':<16} {'ATE RMSE [cm]':>14} {'frames/s':>9} {'keyframes':>10}")
    for label, rmse, fps, nkf, _ in rows:
        ate = f"{rmse * 100:>14.2f}" if rmse is not None else f"{'–':>14}"
        click.echo(f"{label:<16} {ate} {fps:>9.2f} {nkf:>10d}")
    if any(rmse is None for _, rmse, *_ in rows):
        click.echo(f"–: the run never initialised (too little parallax in {frames} frames), so it has no ATE")
    click.echo("")
    click.echo(f"sequence (ground truth, depth, dynamic masks): {seq}")
    for _, _, _, _, paths in rows:
        for p in paths:
            click.echo(f"wrote {p}")
