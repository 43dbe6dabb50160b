"""``droidw map``: a 3D Gaussian map of a tracked run (the work: :func:`droidw_cli.gaussians.build.run_map`)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from droidw_cli.errors import InputError


def _parse_size(ctx, param, value):
    if value is None:
        return None
    parts = value.lower().replace("×", "x").split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise click.BadParameter(f"expected WIDTHxHEIGHT such as 256x192, got {value!r}")
    return int(parts[1]), int(parts[0])


@click.command("map")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=None,
              help="Output folder: static.ply, dynamic.ply, views/, map.json (default RUN/map, where "
                   "`droidw view RUN` finds it).")
@click.option("--minutes", type=float, default=8.0, show_default=True,
              help="Time budget; the map stops early when it is spent (map.json says what ended it).")
@click.option("--steps", type=click.IntRange(min=1), default=200, show_default=True,
              help="Optimisation steps of the static map (a run ended by the steps is deterministic).")
@click.option("--object-steps", type=click.IntRange(min=0), default=20, show_default=True,
              help="Steps per keyframe for the objects' Gaussians.")
@click.option("--size", callback=_parse_size, default=None, metavar="WxH",
              help="Resolution of the map's images (default: half the run's working size).")
@click.option("--holdout-every", type=click.IntRange(min=1), default=20, show_default=True,
              help="Every N-th non-keyframe is a held-out view (scored, never trained on).")
@click.option("--no-masks", is_flag=True, help="Treat every pixel as static (movers leave ghosts; for comparison).")
@click.option("--input", "input_path", type=click.Path(path_type=Path), default=None,
              help="The run's input, when it has moved since `droidw track` (default: the path in run.json).")
@click.option("--rasteriser", default="auto", show_default=True,
              help="auto (gsplat with a CUDA device, else torch), torch or gsplat.")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--quiet", is_flag=True, help="No progress bars.")
def map_command(run_dir, out_dir, minutes, steps, object_steps, size, holdout_every, no_masks, input_path,
                rasteriser, seed, quiet):
    """Fit a 3D Gaussian map to a tracked run: a static map without the movers, plus Gaussians
    for each dynamic object at each keyframe (ADD-SLAM).

    The run's poses stay fixed; keyframe depth initialises the Gaussians.  Every N-th
    non-keyframe is held out and scored (PSNR / SSIM in map.json, pictures in views/).

    \b
    Examples:
      droidw map run/                    # writes run/map/; then: droidw view run/
      droidw map run/ --out map/ --minutes 3 --size 128x96
      droidw map run/ --out map-nomask/ --no-masks
    """
    from droidw_cli.gaussians.build import run_map
    from droidw_cli.gaussians.params import MapParams

    try:
        params = MapParams(size=size, holdout_every=holdout_every, use_masks=not no_masks, steps=steps,
                           object_steps=object_steps, minutes=minutes, seed=seed, rasteriser=rasteriser)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    out_dir = out_dir if out_dir is not None else run_dir / "map"
    progress = not quiet and sys.stderr.isatty()
    doc = run_map(run_dir, out_dir, params, input_path, progress, echo=lambda m: click.echo(m, err=True))
    g, h = doc["gaussians"], doc["heldout"]["mean"]
    click.echo(f"{g['static']} static and {g['dynamic']} object Gaussians, {doc['static']['steps']} steps "
               f"({doc['static']['ended']}), {doc['seconds']['total']:.0f} s")
    if h["psnr_static_pixels"] is not None:
        click.echo(f"held-out frames: PSNR {h['psnr_static_pixels']:.2f} dB on static pixels, "
                   f"{h['psnr_all']:.2f} dB overall")
    click.echo(f"wrote {Path(out_dir) / 'static.ply'}, dynamic.ply, views/, map.json")
