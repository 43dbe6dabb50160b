"""Shared pieces of the tracking benchmarks: run one tracking case, in its own process.

Each case runs in a fresh subprocess so that its peak resident memory
(ru_maxrss) is its own.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def run_case_subprocess(script: str, args: list[str]) -> dict:
    """Run ``script --one ARGS`` and parse the JSON object on its last stdout line."""
    proc = subprocess.run([sys.executable, str(HERE / script), "--one", *args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"case {args} failed:\n{proc.stderr[-2000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def track_source(source, calibration, overrides: list[str], backend: str = "auto", config: str = "default"):
    """Track a frame source with a config (default: ``default``) plus overrides and a BA backend (default
    ``auto``, what ``droidw track`` takes: the native kernels where they build); returns (result, seconds)."""
    from droidw_cli.ba.registry import get_backend
    from droidw_cli.config import load_config
    from droidw_cli.correspondence import get_correspondence_source
    from droidw_cli.features import get_feature_extractor
    from droidw_cli.slam.tracker import Tracker

    cfg = load_config(config, overrides)
    features = get_feature_extractor(cfg.features.name) if cfg.uncertainty.enable else None
    tracker = Tracker(cfg, get_backend(backend), get_correspondence_source(cfg.correspondence), features, progress=False)
    t = time.perf_counter()
    result = tracker.run(source, calibration)
    return result, time.perf_counter() - t


def cached_sequence(cfg, name: str) -> Path:
    """The TUM-style folder of synthetic config ``cfg`` (preset ``name``) in ``benchmarks/.cache``,
    rendered on first use."""
    from droidw_cli.synth.writer import write_sequence

    folder = HERE / ".cache" / f"{name}{'-apart' if cfg.apart else ''}-seed{cfg.seed}-{cfg.frames}"
    if not _is_current(folder, cfg):
        write_sequence(cfg, folder, progress=False, overwrite=True)
    return folder


def _is_current(folder: Path, cfg) -> bool:
    """Whether ``folder`` holds ``cfg`` as rendered by this generator version (else it is rendered again)."""
    import dataclasses
    import json

    from droidw_cli.synth.config import GENERATOR_VERSION, SynthConfig

    try:
        meta = json.loads((folder / "synth.json").read_text())
    except (OSError, ValueError):
        return False
    written = {**dataclasses.asdict(SynthConfig()), **meta.get("config", {})}  # fields added since: their defaults
    return (folder / "rgb.txt").exists() and meta.get("version", 1) == GENERATOR_VERSION and \
        written == json.loads(json.dumps(dataclasses.asdict(cfg)))


def peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def print_table(headers: list[str], rows: list[list]) -> None:
    widths = [max(len(str(h)), *(len(str(r[i])) for r in rows)) for i, h in enumerate(headers)]
    print("| " + " | ".join(str(h).ljust(w) for h, w in zip(headers, widths)) + " |")
    print("|" + "|".join("-" * (w + 2) for w in widths) + "|")
    for r in rows:
        print("| " + " | ".join(str(c).ljust(w) for c, w in zip(r, widths)) + " |")
