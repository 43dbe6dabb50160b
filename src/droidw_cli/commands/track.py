"""``droidw track``: run the SLAM pipeline on a video or image sequence."""

from __future__ import annotations

import resource
import sys
from pathlib import Path

import click

from droidw_cli.commands.options import config_option, set_option
from droidw_cli.io.sources import TUM_DEPTH_SCALE


def peak_memory_mb() -> float:
    """Peak resident memory of this process in MiB (Linux ru_maxrss is in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def depth_config(config_name: str, overrides, depth: bool) -> tuple[str, tuple[str, ...]]:
    """``--depth``: the ``rgbd`` config in place of ``default``, else ``io.use_depth=true`` on the chosen one."""
    overrides = tuple(overrides)
    if not depth:
        return config_name, overrides
    if config_name == "default":
        return "rgbd", overrides
    return config_name, ("io.use_depth=true", *overrides)


#: depth images decoded by :func:`check_depth`, spread evenly over the selected frames
DEPTH_SAMPLES = 8


def open_depth(source, depth_scale: float) -> list[str]:
    """Prepare ``source`` for an RGB-D run: its depth scale, and mis-sized depth images as errors.

    Returns the warnings of :func:`check_depth`."""
    from droidw_cli.errors import InputError

    if not depth_scale > 0:
        raise InputError(f"--depth-scale must be positive, got {depth_scale:g}")
    if not getattr(source, "has_depth", False):
        raise InputError(f"{source.path}: RGB-D mode (--depth, config io.use_depth) needs depth images, and this "
                         f"input has none (a TUM/Bonn folder lists them in depth.txt)")
    notes = check_depth(source, depth_scale)
    source.depth_scale = float(depth_scale)
    source.strict_depth = True
    return notes


#: the median sensor depth (metres) outside which --depth-scale is probably wrong: nearer than depth cameras
#: measure, or farther than indoor RGB-D sensors reach
PLAUSIBLE_DEPTH = (0.2, 10.0)


def check_depth(source, depth_scale: float) -> list[str]:
    """Fail before the run when no frame has usable depth; warnings for frames without a depth image and
    for a median depth no depth camera gives (a wrong ``depth_scale``).

    A run whose every depth pixel is 0 (invalid) would have no metric scale yet be labelled metric.
    Sampled: up to :data:`DEPTH_SAMPLES` paired depth images, evenly over the selection; it is an
    error when none of them holds a non-zero pixel."""
    import numpy as np

    from droidw_cli.errors import InputError
    from droidw_cli.io.frames import decode_depth

    files = source.depth_files()
    paired = [p for p in files if p is not None]
    if not paired:
        raise InputError(f"{source.path}: none of the {len(files)} selected frames has a depth image "
                         f"(depth.txt lists none close enough to the frames' timestamps in rgb.txt)")
    notes = []
    if len(paired) < len(files):
        notes.append(f"{len(files) - len(paired)} of the {len(files)} selected frames have no depth image close "
                     f"to their timestamp; they are tracked without depth")
    picks = np.unique(np.round(np.linspace(0, len(paired) - 1, min(DEPTH_SAMPLES, len(paired)))).astype(int))
    medians = []
    for i in picks:
        raw = decode_depth(paired[i], depth_scale)
        if raw is not None and bool((raw > 0).any()):
            medians.append(float(np.median(raw[raw > 0])))
    if not medians:
        raise InputError(f"{source.path}: the depth images hold no depth: {len(picks)} of them, spread over the "
                         f"sequence (e.g. {paired[picks[0]].name}), are unreadable or 0 (invalid) everywhere; check "
                         f"the depth folder, or run without --depth")
    median = float(np.median(medians))
    lo, hi = PLAUSIBLE_DEPTH
    if not lo <= median <= hi:
        notes.append(f"the median sensor depth is {median:.3g} m with --depth-scale {depth_scale:g}, outside the "
                     f"{lo:g}-{hi:g} m depth cameras measure: check --depth-scale (5000: TUM, Bonn; 1000: millimetres)")
    return notes


def run_track(input_path, out_dir, calib=None, backend="auto", config_name="default", overrides=(),
              stride=None, start=None, max_frames=None, progress=True, echo=click.echo, depth=False,
              depth_scale=TUM_DEPTH_SCALE):
    """The work behind ``droidw track`` (also used by ``droidw demo`` and the benchmarks).

    ``depth``: RGB-D mode (:func:`depth_config`); ``depth_scale``: depth PNG units per metre.
    Returns (TrackResult, list of written paths).
    """
    import dataclasses

    import torch

    from droidw_cli.ba.registry import resolve_backend
    from droidw_cli.config import load_config
    from droidw_cli.correspondence import get_correspondence_source
    from droidw_cli.export.run_files import run_info, write_run
    from droidw_cli.features import get_feature_extractor
    from droidw_cli.io.calibration import load_calibration
    from droidw_cli.io.frames import open_source
    from droidw_cli.io.outputs import check_output_folder
    from droidw_cli.slam.tracker import Tracker

    config_name, overrides = depth_config(config_name, overrides, depth)
    cfg = load_config(config_name, overrides)
    io = cfg.io
    io = dataclasses.replace(io, **{k: v for k, v in (("stride", stride), ("start", start), ("max_frames", max_frames))
                                    if v is not None})
    cfg = dataclasses.replace(cfg, io=io)
    torch.manual_seed(cfg.seed)
    check_output_folder(out_dir)  # before the run, not after it
    # --calib (a file or auto) wins over a calibration found with the input; one droidw cannot read is then
    # a warning, and without --calib an error
    source = open_source(input_path, stride=io.stride, start=io.start, max_frames=io.max_frames, fps=io.fps,
                         strict_calibration=calib is None)
    notes = open_depth(source, depth_scale) if io.use_depth else []
    if calib is None:  # the calibration that came with the data, else estimate it
        calibration = source.intrinsics_hint
        if calibration is not None:
            calibration.validate(source.size, "the input's calibration")
    else:
        if source.calibration_problem is not None:
            notes.append(f"ignored the input's calibration, --calib {calib} is used ({source.calibration_problem})")
        calibration = None if calib == "auto" else load_calibration(calib, image_size=source.size,
                                                                       camera=source.calibration_camera)
    choice = resolve_backend(backend)
    ba_backend = choice.backend
    if choice.requested == "auto":  # say which one auto picked, and why not the others
        echo(f"droidw: {choice.describe()}", err=True)
    corr = get_correspondence_source(cfg.correspondence)
    features = get_feature_extractor(cfg.features.name) if cfg.uncertainty.enable else None
    result = Tracker(cfg, ba_backend, corr, features, progress=progress).run(source, calibration)
    result.warnings = [*notes, *result.warnings]
    info = run_info(result, cfg.to_dict(), ba_backend.name, str(input_path), peak_memory_mb())
    info["calibration"]["source"] = (("estimated" if result.focal_estimated else "guessed")
                                     if result.calibration_estimated else (str(calib) if calib else "input"))
    info["backend_choice"] = {"requested": choice.requested, "passed_over": list(choice.passed_over)}
    paths = write_run(out_dir, result, info)
    return result, paths


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
              help="BA backend: auto (cuda when it is available and builds, else cpu; stderr and run.json "
                   "say which), cpu, cuda (see `droidw backends`).")
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
