"""A real `droidw track` run of a short synthetic clip with walkers, for the tests of what reads runs."""

from __future__ import annotations

from pathlib import Path


def track_tiny_clip(root: Path, frames: int) -> Path:
    """Render the ``dynamic`` preset (seed 3, 160×120, 10 fps, ``frames`` frames) into ``root/seq`` and track it
    with the ``fast`` config on the cpu backend into ``root/run`` (one torch thread: seconds); returns the run."""
    import torch

    from droidw_cli.synth import SynthConfig, write_sequence
    from droidw_cli.track import run_track

    cfg = SynthConfig.preset("dynamic", seed=3, frames=frames, width=160, height=120, fps=10.0)
    write_sequence(cfg, root / "seq", video=False, progress=False)
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run_track(root / "seq", root / "run", None, "cpu", "fast",
                  ("io.target_area=19200", "motion_filter.thresh=1.0", "frontend.keyframe_thresh=1.0"),
                  progress=False)
    finally:
        torch.set_num_threads(before)
    return root / "run"
