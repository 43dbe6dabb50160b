"""``droidw track``: run the SLAM pipeline on a video or image sequence (the work: :func:`droidw_cli.track.run_track`)."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from droidw_cli.commands.options import config_option, set_option
from droidw_cli.io.sources import TUM_DEPTH_SCALE


@click.command("track")
@click.argument("input_path", metavar="INPUT", type=click.Path(path_type=Path))
@click.option("--out", "out_dir", type=click.Path(path_type=Path), default=Path("droidw-run"), show_default=True,
              help="Output folder: traj.txt, keyframes.npz, calib.txt, run.json.")
@click.option("--calib", default=None, metavar="FILE|auto",
              help="Calibration file (fx fy cx cy [k1 k2 p1 p2 [k3]], YAML, or KITTI's calib.txt: P0, P2 when "
                   "image_2 is read), or 'auto' to estimate the focal length; it wins over a calibration found "
                   "with the input.  Default: the calibration found with the input (calib.txt, EuRoC sensor.yaml, "
                   "KITTI calib.txt), else auto.")
@click.option("--backend", default="auto", show_default=True,
              help="BA backend: auto (cuda when it is available and builds, else native C++ kernels where a "
                   "compiler builds them, else cpu; stderr and run.json say which), native (falls back to cpu "
                   "without a compiler, and says so), cpu, cuda (see `droidw backends`).")
@config_option
@set_option
@click.option("--depth", is_flag=True,
              help="RGB-D mode: the sensor depth feeds the depth prior and fixes the metric scale (the same as "
                   "--config rgbd; with another --config it adds io.use_depth=true).  Evaluate with --align se3.")
@click.option("--depth-scale", type=float, default=TUM_DEPTH_SCALE, show_default=True,
              help="Depth PNG units per metre (5000: TUM, Bonn).")
@click.option("--stride", type=int, default=None, help="Use every N-th frame.")
@click.option("--start", type=int, default=None, help="Skip the first N frames.")
@click.option("--max-frames", type=int, default=None, help="Stop after N frames (0 = all).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def track(input_path, out_dir, calib, backend, config_name, overrides, depth, depth_scale, stride, start, max_frames,
          quiet):
    """Track INPUT (a video, an image folder, a TUM/Bonn, EuRoC or KITTI odometry folder).

    Writes a camera-to-world pose for every input frame (TUM format, the
    input's own timestamps) plus the keyframes' depth and uncertainty.

    \b
    Examples:
      droidw track video.mp4 --calib auto --out run/
      droidw track rgbd_dataset_freiburg3_walking_xyz/ --calib calib.txt --config tum --out run/
      droidw track rgbd_dataset_freiburg3_walking_xyz/ --calib calib.txt --depth --out run-rgbd/
      droidw track frames/ --set uncertainty.enable=false --out baseline/
      droidw track kitti/sequences/00/ --out run-00/
    """
    from droidw_cli.track import run_track

    progress = not quiet and sys.stderr.isatty()
    result, paths = run_track(input_path, out_dir, calib, backend, config_name, overrides, stride, start,
                              max_frames, progress, depth=depth, depth_scale=depth_scale)
    for w in result.warnings:
        click.echo(f"droidw: warning: {w}", err=True)
    click.echo(f"{len(result.timestamps)} frames, {len(result.kf_index)} keyframes, "
               f"{result.fps:.1f} frames/s end to end")
    if result.calibration_estimated:
        c = result.calibration
        how = "estimated" if result.focal_estimated else "guessed (not estimated)"
        click.echo(f"{how} calibration: fx={c.fx:.2f} fy={c.fy:.2f} cx={c.cx:.2f} cy={c.cy:.2f}")
    for p in paths:
        click.echo(f"wrote {p}")
