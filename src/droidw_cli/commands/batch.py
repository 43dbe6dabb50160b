"""``droidw batch``: track (and evaluate) every sequence of a manifest, one Ray task each."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import click

from droidw_cli.commands.options import set_option


def _default_workers() -> int:
    from droidw_cli.batch import ray_available

    return (os.cpu_count() or 1) if ray_available() else 1


@click.command("batch")
@click.argument("manifest", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path, file_okay=False), required=True,
              help="Output folder: one folder per sequence, summary.csv, summary.md.")
@click.option("--address", default=None, metavar="auto|ray://HOST:PORT",
              help="Join this Ray cluster instead of starting a local runtime.")
@click.option("--workers", type=click.IntRange(min=1), default=None,
              help="CPUs of the local Ray runtime [all CPUs with Ray installed, else 1]; 1 runs the rows in order "
                   "in this process, without Ray.")
@click.option("--threads", type=click.IntRange(min=1), default=1, show_default=True,
              help="Torch threads per sequence; each Ray task asks for that many CPUs.")
@click.option("--config", "config_name", default=None, metavar="NAME|PATH",
              help="Config for rows without a 'config' column [default].")
@set_option
@click.option("--backend", default="auto", show_default=True, help="BA backend for every sequence.")
@click.option("--force", is_flag=True, help="Run again the sequences a previous run finished.")
@click.option("--quiet", is_flag=True, help="No progress bar or per-sequence lines.")
def batch(manifest, out_dir, address, workers, threads, config_name, overrides, backend, force, quiet):
    """Track every sequence of MANIFEST (YAML or CSV), then evaluate those with a ground truth.

    Each row has `input` and optionally `name`, `calib`, `gt`, `align`
    (default: se3 for a metric RGB-D run, else sim3), `config`, `depth`
    (true: RGB-D mode, as `track --depth`), `depth_scale`, `set` (KEY=VALUE
    overrides) or override columns such as `frontend.window`.  --set applies
    to every row, before the row's own overrides.  Exit code 1 when a
    sequence failed.

    \b
    Examples:
      droidw batch tum.yaml --out runs/ --workers 8
      droidw batch videos.csv --out runs/ --address auto --threads 2
      droidw batch tum.yaml --out runs/ --workers 1 --set uncertainty.enable=false
    """
    import dataclasses

    from droidw_cli.batch import BatchOptions, load_manifest, run_batch
    from droidw_cli.batch.runner import require_ray
    from droidw_cli.config import load_config

    rows = load_manifest(manifest)
    load_config(config_name or "default", overrides)  # a bad --config or --set stops the batch before it starts
    rows = [dataclasses.replace(r, config=r.config or config_name or "default",
                                overrides=tuple(overrides) + r.overrides) for r in rows]
    if workers is None:
        workers = _default_workers()
        if workers == 1 and address is None and not quiet:
            click.echo("Ray is not installed: running the sequences in order "
                       "(pip install 'droidw[ray]' to run them in parallel)", err=True)
    if address is not None:
        require_ray("--address")
    progress = not quiet and sys.stderr.isatty()

    def report(rec: dict) -> None:
        if quiet:
            return
        if rec.get("status") == "ok":
            ate = "" if rec.get("ate_rmse_m") is None else f", ATE {100 * rec['ate_rmse_m']:.2f} cm"
            line = f"{rec['name']}: ok, {rec.get('keyframes')} keyframes, {rec.get('fps', 0):.2f} frames/s{ate}"
        else:
            line = f"{rec['name']}: {rec.get('status')}: {rec.get('error')}"
        if progress:
            from tqdm import tqdm

            tqdm.write(line)
        else:
            click.echo(line)

    opts = BatchOptions(out=out_dir, workers=workers, address=address, threads=threads, force=force,
                        backend=backend)
    records = run_batch(rows, opts, progress=progress, report=report)
    ok = sum(r.get("status") == "ok" for r in records)
    reused = sum(bool(r.get("reused")) for r in records)
    note = f" ({reused} finished earlier, skipped; --force runs them again)" if reused else ""
    click.echo(f"{ok} of {len(records)} sequences ok{note}; summary: {out_dir / 'summary.md'}")
    if ok < len(records):
        sys.exit(1)
