"""``droidw export``: point clouds, uncertainty overlays and datasets for 3DGS trainers from a run folder."""

from __future__ import annotations

from pathlib import Path

import click

from droidw_cli.errors import InputError
from droidw_cli.io.outputs import check_output_file, check_output_folder


@click.group("export")
def export() -> None:
    """Export a run: PLY point clouds, dynamic objects, uncertainty overlays, a rendered view of the cloud,
    datasets for 3DGS trainers (nerfstudio, COLMAP) with the movers masked out.

    \b
    Examples:
      droidw export ply                      # inside a run folder: ./static.ply
      droidw export ply run/ --what dynamic --out dynamic.ply
      droidw export objects run/ --out objects.json
      droidw export uncertainty run/ --out overlays/ --video
      droidw export render run/ --out cloud.png --what all
      droidw export nerfstudio run/ --out ns/        # then: ns-train splatfacto --data ns/
      droidw export colmap run/ --out colmap/
    """


@export.command("ply")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out", type=click.Path(path_type=Path), default=None,
              help="Output PLY (default ./static.ply, ./dynamic.ply or ./points.ply).")
@click.option("--what", type=click.Choice(["static", "dynamic", "all"]), default="static", show_default=True)
@click.option("--max-uncertainty", type=float, default=0.8, show_default=True,
              help="Static points need u below this (0.8 is where the BA weighting starts to cut in).")
@click.option("--min-views", type=int, default=2, show_default=True, help="Neighbouring keyframes that must agree.")
@click.option("--stride", type=int, default=1, show_default=True, help="Use every N-th keyframe.")
def ply(run_dir, out, what, max_uncertainty, min_views, stride):
    """Write the keyframes' points as a binary PLY in world coordinates.

    The static cloud keeps points with low uncertainty that several views
    agree on and that were never masked dynamic; the dynamic cloud holds the
    masked points with their keyframe time and object id (vertex properties
    `t`, `object_id`), so a viewer can play each object over time; `all`
    writes both with a `dynamic` flag.
    """
    from droidw_cli.export.pointcloud import CloudParams, build_cloud, write_ply
    from droidw_cli.export.run_files import load_run

    if stride < 1 or min_views < 0:
        raise InputError("--stride must be ≥ 1 and --min-views ≥ 0")
    default_name = {"static": "static.ply", "dynamic": "dynamic.ply", "all": "points.ply"}[what]
    out = out or Path(default_name)
    check_output_file(out)
    npz = load_run(run_dir)
    cloud = build_cloud(npz, CloudParams(max_uncertainty=max_uncertainty, min_views=min_views, stride=stride))
    part = cloud.part(what)
    n = write_ply(out, part, with_time=what != "static", with_flag=what == "all")
    click.echo(f"wrote {n} points to {out}")


@export.command("objects")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("objects.json"), show_default=True)
def objects(run_dir, out):
    """Write the run's dynamic objects as JSON: per object id its first and last frame and time, and per
    keyframe its image centre and world centroid (schema in docs/formats.md)."""
    from droidw_cli.export.objects import format_objects, objects_json
    from droidw_cli.export.run_files import load_run, run_is_metric
    from droidw_cli.io.trajectory import atomic_write_text

    check_output_file(out)
    npz = load_run(run_dir)
    try:
        doc = objects_json(npz, run_is_metric(run_dir))
    except ValueError as exc:
        raise InputError(f"{run_dir}: {exc}") from None
    atomic_write_text(out, format_objects(doc))
    click.echo(f"wrote {len(doc['objects'])} objects to {out}")


@export.command("uncertainty")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("uncertainty"), show_default=True)
@click.option("--video", is_flag=True, help="Also write overlay.mp4.")
def uncertainty(run_dir, out, video):
    """Write a PNG overlay of the uncertainty u for each keyframe (with a legend)."""
    from droidw_cli.export.overlay import write_overlays
    from droidw_cli.export.run_files import load_run

    check_output_folder(out)
    npz = load_run(run_dir)
    try:
        paths = write_overlays(npz, out, video=video)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    click.echo(f"wrote {len(paths)} files to {out}")


def _parse_size(ctx, param, value: str) -> tuple[int, int]:
    parts = value.lower().replace("×", "x").split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
        raise click.BadParameter(f"expected WIDTHxHEIGHT such as 640x480, got {value!r}")
    return int(parts[0]), int(parts[1])


@export.command("render")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("cloud.png"), show_default=True)
@click.option("--what", type=click.Choice(["static", "all"]), default="static", show_default=True,
              help="The static cloud, or every point with the dynamic ones in red.")
@click.option("--size", callback=_parse_size, default="640x480", show_default=True, metavar="WxH")
@click.option("--azimuth", type=float, default=0.0, show_default=True,
              help="Degrees about the scene's up axis; 0 looks the way the cameras looked.")
@click.option("--elevation", type=float, default=25.0, show_default=True, help="Degrees above the horizontal.")
@click.option("--zoom", type=float, default=1.0, show_default=True)
@click.option("--point-size", type=int, default=2, show_default=True, help="Splat side in pixels.")
@click.option("--no-trajectory", is_flag=True, help="Do not draw the keyframe path.")
@click.option("--max-uncertainty", type=float, default=0.8, show_default=True, help="As for `export ply`.")
@click.option("--min-views", type=int, default=2, show_default=True, help="As for `export ply`.")
@click.option("--stride", type=int, default=1, show_default=True, help="Use every N-th keyframe.")
def render(run_dir, out, what, size, azimuth, elevation, zoom, point_size, no_trajectory, max_uncertainty,
           min_views, stride):
    """Render the run's point cloud from a virtual camera into a PNG (headless).

    The camera orbits the middle of the cloud and frames it; the keyframe
    path is drawn in orange.
    """
    from droidw_cli.export.pointcloud import CloudParams, build_cloud
    from droidw_cli.export.render import RenderParams, render_cloud, write_png
    from droidw_cli.export.run_files import load_run

    if stride < 1 or min_views < 0:
        raise InputError("--stride must be ≥ 1 and --min-views ≥ 0")
    try:
        params = RenderParams(width=size[0], height=size[1], azimuth=azimuth, elevation=elevation, zoom=zoom,
                              point_size=point_size)
    except ValueError as exc:
        raise InputError(str(exc)) from None
    check_output_file(out)
    npz = load_run(run_dir)
    try:
        cloud = build_cloud(npz, CloudParams(max_uncertainty=max_uncertainty, min_views=min_views, stride=stride))
    except ValueError as exc:
        raise InputError(f"{run_dir}: {exc}") from None
    part = cloud.part(what)  # the points `export ply --what` writes
    if len(part.xyz) == 0:
        raise InputError(f"{run_dir}: no {what} points to render (try --what all or a larger --max-uncertainty)")
    image = render_cloud(part.xyz, part.rgb, npz["poses_c2w"], params,
                         dynamic=None if what == "static" else part.dynamic, trajectory=not no_trajectory)
    write_png(out, image)
    click.echo(f"rendered {len(part.xyz)} points to {out} ({size[0]}x{size[1]})")


def _trainer_options(func):
    """The options `export nerfstudio` and `export colmap` share."""
    options = [
        click.option("--input", "input_path", type=click.Path(path_type=Path), default=None,
                     help="Where the run's frames are now (default: run.json's input)."),
        click.option("--masks", type=click.Choice(["dynamic", "masked"]), default="dynamic", show_default=True,
                     help="dynamic: the run's output mover masks; masked: those and every pixel BA zeroed in the "
                          "loop (what the static cloud leaves out: far more of the frame)."),
        click.option("--mask-dilate", type=click.IntRange(min=0), default=None, metavar="PX",
                     help="Grow the movers by this many input pixels (the 1/8-grid masks cut through outlines) "
                          "[default: half a grid cell, 4 working pixels]."),
        click.option("--max-uncertainty", type=float, default=0.8, show_default=True,
                     help="As for `export ply` (the static points)."),
        click.option("--min-views", type=click.IntRange(min=0), default=2, show_default=True,
                     help="As for `export ply`."),
        click.option("--quiet", is_flag=True, help="No progress bar."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


@export.command("nerfstudio")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("nerfstudio"), show_default=True,
              help="A new (or empty) folder.")
@click.option("--depth-scale", type=float, default=5000.0, show_default=True,
              help="RGB-D runs: the depth images' units per metre, as given to `droidw track --depth-scale`.")
@_trainer_options
def nerfstudio(run_dir, out, depth_scale, input_path, masks, mask_dilate, max_uncertainty, min_views, quiet):
    """Write the run's keyframes as a nerfstudio dataset: transforms.json, images/, masks/ (black = the
    movers, for the trainer to ignore), depths/ (RGB-D runs) and points.ply (the static cloud).

    Every keyframe becomes a frame, at the input resolution; the poses are camera-to-world in nerfstudio's
    OpenGL camera axes.  Train with e.g. `ns-train splatfacto --data OUT`.
    """
    import sys

    from droidw_cli.export.nerfstudio import export_nerfstudio
    from droidw_cli.export.pointcloud import CloudParams

    if not depth_scale > 0:
        raise InputError(f"--depth-scale must be positive, got {depth_scale:g}")
    doc = export_nerfstudio(run_dir, out, input_path=input_path, masks=masks, dilate=mask_dilate,
                            depth_scale=depth_scale,
                            cloud=CloudParams(max_uncertainty=max_uncertainty, min_views=min_views),
                            progress=not quiet and sys.stderr.isatty())
    frames = doc["frames"]
    extras = [f"{sum('mask_path' in f for f in frames)} masks", f"{sum('depth_file_path' in f for f in frames)} depth"]
    if "ply_file_path" not in doc:
        extras.append("no static points")
    click.echo(f"wrote {len(frames)} frames ({', '.join(extras)}) to {out / 'transforms.json'}")


@export.command("colmap")
@click.argument("run_dir", type=click.Path(path_type=Path), default=Path("."), required=False)
@click.option("--out", "out", type=click.Path(path_type=Path), default=Path("colmap"), show_default=True,
              help="A new (or empty) folder.")
@_trainer_options
def colmap(run_dir, out, input_path, masks, mask_dilate, max_uncertainty, min_views, quiet):
    """Write the run's keyframes as a COLMAP text model: sparse/0/{cameras,images,points3D}.txt (the static
    points), images/ and masks/ (COLMAP's masks/NAME.png, black = the movers).

    Every keyframe becomes an image, at the input resolution; for gsplat's or the original 3DGS trainer.
    """
    import sys

    from droidw_cli.export.colmap import export_colmap
    from droidw_cli.export.pointcloud import CloudParams

    summary = export_colmap(run_dir, out, input_path=input_path, masks=masks, dilate=mask_dilate,
                            cloud=CloudParams(max_uncertainty=max_uncertainty, min_views=min_views),
                            progress=not quiet and sys.stderr.isatty())
    click.echo(f"wrote {summary['images']} images ({summary['masks']} masks), {summary['points']} static points "
               f"({summary['camera']} camera) to {out / 'sparse' / '0'}")
