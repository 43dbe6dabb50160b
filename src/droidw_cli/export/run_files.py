"""Writes a ``droidw track`` run folder, all-or-nothing, and reads it back (:func:`load_run`).

Files: ``traj.txt`` (TUM, camera-to-world, every frame), ``keyframes.npz``,
``calib.txt`` and ``run.json``.  Everything is written into a hidden
temporary folder beside the output and moved into place only when all files
are complete, so a failed run leaves no half-written output.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import tempfile
from pathlib import Path

import numpy as np

from droidw_cli import __version__
from droidw_cli.config import GRID_UNIT
from droidw_cli.errors import InputError
from droidw_cli.io.calibration import format_calibration
from droidw_cli.io.trajectory import Trajectory, format_trajectory

RUN_FILES = ("traj.txt", "keyframes.npz", "calib.txt", "run.json")


def keyframe_arrays(result) -> dict[str, np.ndarray]:
    """The arrays stored in ``keyframes.npz`` (copies only where the result holds another dtype)."""
    arrays = {
        "index": result.kf_index,
        "timestamps": result.kf_timestamps,
        "poses_c2w": result.kf_poses_c2w,
        "disps": result.kf_disps.astype(np.float32, copy=False),
        "intrinsics": np.asarray(result.intrinsics_work, dtype=np.float64),
        "work_size": np.array(result.work_size, dtype=np.int64),
        "images": np.asarray(result.kf_images, dtype=np.uint8),  # the result keeps them JPEG-encoded
        "confidence": result.kf_confidence.astype(np.float16, copy=False),
    }
    if result.kf_dynamic is not None:
        arrays["dynamic"] = result.kf_dynamic.astype(bool, copy=False)
        arrays["object_ids"] = result.kf_object_ids.astype(np.int32)  # the result keeps int16
        arrays["objects"] = result.objects.astype(np.float64, copy=False)
        if getattr(result, "kf_masked", None) is not None:
            arrays["masked"] = result.kf_masked.astype(bool, copy=False)
    if result.kf_uncertainty is not None:
        arrays["uncertainty"] = result.kf_uncertainty.astype(np.float32, copy=False)
        arrays["features"] = result.kf_features
        arrays["theta"] = result.theta
    return arrays


def run_info(result, config: dict, backend: str, source: str, peak_mb: float) -> dict:
    """The content of ``run.json``."""
    import cv2
    import torch

    return {
        "droidw": __version__,
        "versions": {"python": platform.python_version(), "torch": torch.__version__, "opencv": cv2.__version__,
                     "numpy": np.__version__},
        "input": source,
        "backend": backend,
        "config": config,
        "flow_threshold_unit": GRID_UNIT,
        "frames": int(len(result.timestamps)),
        "keyframes": int(len(result.kf_index)),
        "initialised": bool(result.initialised),
        "metric": bool(result.metric),
        "scale": ("metric: sensor depth fixes the scale; evaluate with --align se3" if result.metric
                  else "arbitrary (monocular); evaluate with --align sim3"),
        "calibration": {"fx": result.calibration.fx, "fy": result.calibration.fy,
                        "cx": result.calibration.cx, "cy": result.calibration.cy},
        "intrinsics_working": [float(v) for v in result.intrinsics_work],
        "working_size": list(result.work_size),
        "seconds_per_stage": result.timings,
        "wall_seconds": round(result.wall_time, 3),
        "fps": round(result.fps, 3),
        "peak_memory_mb": round(peak_mb, 1),
        "warnings": result.warnings,
    }


def write_run(out_dir: str | Path, result, info: dict) -> list[Path]:
    """Write the run files into ``out_dir`` atomically; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".droidw-", dir=out))
    try:
        traj = Trajectory(result.timestamps, result.poses_c2w)
        (tmp / "traj.txt").write_text(format_trajectory(traj, "tum"))
        with open(tmp / "keyframes.npz", "wb") as fh:
            np.savez_compressed(fh, **keyframe_arrays(result))
        (tmp / "calib.txt").write_text(format_calibration(result.calibration))
        (tmp / "run.json").write_text(json.dumps(info, indent=2, default=float) + "\n")
        paths = []
        for name in RUN_FILES:
            os.replace(tmp / name, out / name)
            paths.append(out / name)
        return paths
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def load_run(run_dir: Path) -> dict:
    """The arrays of ``RUN_DIR/keyframes.npz`` (a clear error if it is missing or unreadable)."""
    path = run_dir / "keyframes.npz" if run_dir.is_dir() else run_dir
    if not path.is_file():
        raise InputError(f"{path}: no such file; run `droidw track ... --out {run_dir}` first")
    try:
        with np.load(path) as z:
            return {k: z[k] for k in z.files}
    except Exception as exc:  # noqa: BLE001 - any unreadable npz is a user-facing error
        raise InputError(f"{path}: cannot read keyframes ({exc})") from None


def run_is_metric(run_dir: Path) -> bool:
    """``run.json``'s ``metric`` flag (False when there is no readable run.json)."""
    path = (run_dir if run_dir.is_dir() else run_dir.parent) / "run.json"
    try:
        return bool(json.loads(path.read_text()).get("metric", False))
    except (OSError, ValueError, AttributeError):
        return False
