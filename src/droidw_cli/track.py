"""One tracking run as a library call: config, input, calibration, backend, the tracker, the run files.

:func:`run_track` is what ``droidw track`` does; ``droidw demo``, ``droidw batch`` and the benchmarks call
it too.  The pipeline itself is :class:`droidw_cli.slam.tracker.Tracker`.
"""

from __future__ import annotations

import resource

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


def run_track(input_path, out_dir, calib=None, backend="auto", config_name="default", overrides=(),
              stride=None, start=None, max_frames=None, progress=True, echo=None, depth=False,
              depth_scale=TUM_DEPTH_SCALE):
    """The work behind ``droidw track`` (also used by ``droidw demo``, ``droidw batch`` and the benchmarks).

    ``depth``: RGB-D mode (:func:`depth_config`); ``depth_scale``: depth PNG units per metre;
    ``echo``: where the backend choice is said (default ``click.echo``).
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
    from droidw_cli.io.input import open_source
    from droidw_cli.io.outputs import check_output_folder
    from droidw_cli.io.rgbd import open_depth
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
    if echo is None:
        import click

        echo = click.echo
    ba_backend = choice.backend
    if choice.requested == "auto" or choice.passed_over:  # say which one auto picked (or fell back to), and why
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
