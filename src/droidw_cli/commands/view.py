"""``droidw view``: a run in the rerun viewer, or in an .rrd file."""

from __future__ import annotations

import sys
from pathlib import Path

import click


@click.command("view")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--save", "save_path", type=click.Path(path_type=Path, dir_okay=False), default=None, metavar="FILE.rrd",
              help="Write a rerun file instead of opening the viewer (works on a headless machine).")
@click.option("--stride", type=click.IntRange(min=1), default=1, show_default=True,
              help="Use every N-th keyframe's points.")
@click.option("--map", "map_dir", type=click.Path(path_type=Path, file_okay=False), default=None,
              help="A `droidw map` folder to show as ellipsoids (default: RUN/map when it exists).")
@click.option("--quiet", is_flag=True, help="No progress bars.")
def view(run_dir, save_path, stride, map_dir, quiet):
    """Show a `droidw track` run in rerun: trajectory, keyframe frusta, static and
    dynamic points, images with the uncertainty overlay on a timeline; and the
    Gaussian map of `droidw map` when the run has one.

    Needs the view extra: pip install 'droidw[view]'.

    \b
    Examples:
      droidw view run/                   # opens the rerun viewer
      droidw view run/ --save run.rrd    # headless; later: rerun run.rrd
    """
    from droidw_cli.export.rrd import load_run_folder, require_rerun, save_rrd, show
    from droidw_cli.export.rrd_map import find_map

    from droidw_cli.io.outputs import check_output_file

    require_rerun()
    if save_path is not None:
        check_output_file(save_path)
    run = load_run_folder(run_dir)
    progress = not quiet and sys.stderr.isatty()
    gmap = find_map(run_dir, map_dir)
    counts = (save_rrd(run, save_path, progress, stride, gmap) if save_path is not None
              else show(run, progress, stride, gmap))
    if counts.get("note"):
        click.echo(f"droidw: warning: {counts['note']}", err=True)
    click.echo(f"{counts['frames']} poses, {counts['keyframes']} keyframes, {counts['static_points']} static and "
               f"{counts['dynamic_points']} dynamic points" +
               (f", {counts['gaussians']} Gaussians of {gmap}" if "gaussians" in counts else ""))
    if save_path is not None:
        click.echo(f"wrote {save_path} (open it with `rerun {save_path}`)")
