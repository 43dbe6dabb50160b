"""Small tracked synthetic runs for the trainer exports' tests (`export nerfstudio`, `export colmap`).

A 20-frame 320×240 clip of the `dynamic` preset (walkers), tracked at a 160×120 working size (so the
exports must scale the intrinsics and the 1/8-grid masks up by 2), monocular and RGB-D.  Each run is
made once per test session (a few seconds, one torch thread) and shared by the test modules.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

SIZE = (240, 320)  # input H, W
WORK_AREA = 19200  # 120 x 160 working size


def tracked_run(tmp_path_factory, depth: bool = False) -> tuple[Path, Path]:
    """``(sequence folder, run folder)``, tracked on first use in this session."""
    import torch

    from droidw_cli.synth import SynthConfig, write_sequence
    from droidw_cli.track import run_track

    root = tmp_path_factory.getbasetemp() / "trainer-runs"
    seq, run = root / "seq", root / ("run-rgbd" if depth else "run")
    if (run / "run.json").is_file():
        return seq, run
    if not (seq / "synth.json").is_file():
        cfg = SynthConfig.preset("dynamic", seed=3, frames=20, width=SIZE[1], height=SIZE[0], fps=10.0)
        write_sequence(cfg, seq, video=False, progress=False)
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        run_track(seq, run, None, "cpu", "fast",
                  (f"io.target_area={WORK_AREA}", "motion_filter.thresh=1.0", "frontend.keyframe_thresh=1.0"),
                  progress=False, depth=depth)
    finally:
        torch.set_num_threads(before)
    return seq, run


def listing(seq: Path, name: str) -> list[Path]:
    """The files of ``seq/NAME.txt`` (rgb, depth, mask) in order."""
    lines = (seq / f"{name}.txt").read_text().splitlines()
    return [seq / line.split()[1] for line in lines if line.strip() and not line.startswith("#")]


def gt_mask(seq: Path, frame: int) -> np.ndarray:
    """The generator's ground-truth mover mask of a frame, (H, W) bool."""
    return cv2.imread(str(listing(seq, "mask")[frame]), cv2.IMREAD_GRAYSCALE) > 127


def run_arrays(run: Path) -> dict:
    with np.load(run / "keyframes.npz") as z:
        return {k: z[k] for k in z.files}


def calib_values(run: Path) -> list[float]:
    return [float(v) for v in (run / "calib.txt").read_text().split()]


def cell_centres_in_input(run: Path, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Input-pixel (OpenCV: centres at integers) position of BA-grid cell centres, by the run's own intrinsics:
    working pixel 8c + 3.5 → normalised with the working intrinsics → input pixel with calib.txt."""
    fx, fy, cx, cy = calib_values(run)[:4]
    fxw, fyw, cxw, cyw = run_arrays(run)["intrinsics"]
    return cx + fx * ((8 * cols + 3.5) - cxw) / fxw, cy + fy * ((8 * rows + 3.5) - cyw) / fyw


def opencv_projection(run: Path, k: int, xyz: np.ndarray) -> np.ndarray:
    """The run's own projection of world points into keyframe k: its OpenCV camera-to-world pose and its
    working intrinsics, the result carried to input pixels (OpenCV convention), (P, 2)."""
    arrays = run_arrays(run)
    w2c = np.linalg.inv(arrays["poses_c2w"][k])
    cam = xyz @ w2c[:3, :3].T + w2c[:3, 3]
    fxw, fyw, cxw, cyw = arrays["intrinsics"]
    uw, vw = fxw * cam[:, 0] / cam[:, 2] + cxw, fyw * cam[:, 1] / cam[:, 2] + cyw
    fx, fy, cx, cy = calib_values(run)[:4]
    return np.stack([cx + fx * (uw - cxw) / fxw, cy + fy * (vw - cyw) / fyw], -1)


def with_calibration(run: Path, dest: Path, values: list[float]) -> Path:
    """A copy of run folder ``run`` at ``dest`` whose calib.txt holds ``values``."""
    import shutil

    shutil.copytree(run, dest)
    (dest / "calib.txt").write_text(" ".join(repr(v) for v in values) + "\n")
    return dest


def with_input(run: Path, dest: Path, input_path: str) -> Path:
    """A copy of run folder ``run`` at ``dest`` whose run.json names another input."""
    import shutil

    shutil.copytree(run, dest)
    info = json.loads((dest / "run.json").read_text())
    info["input"] = input_path
    (dest / "run.json").write_text(json.dumps(info))
    return dest
