"""The per-frame files of a trainer export: full-size images, mover masks and metric depth.

For every keyframe (in order) :func:`write_frame_files` writes, into a
(staging) folder,

* ``images/NAME`` — the input frame, 8-bit RGB PNG at the input resolution;
* the mask (where the run has masks) under the name the layout gives —
  single-channel PNG, 0 = ignore (movers), 255 = static (:mod:`.trainer_masks`);
* with ``depth_scale`` (RGB-D runs), ``depths/NAME`` — the sensor's z-depth as
  a 16-bit PNG in millimetres (0 = invalid, also for depth beyond 65.535 m).

NAME is ``frame_NNNNNN.png``, NNNNNN the frame's position in the run's frame
selection (``keyframes.npz`` ``index``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from droidw_cli.export.trainer_masks import grid_lookup, mask_image
from droidw_cli.export.trainer_run import TrainerRun, check_depth_scale, frame_name, keyframe_frames

#: depth PNG units per metre in the exports (millimetres; nerfstudio's depth_unit_scale_factor is its inverse)
DEPTH_UNITS_PER_METRE = 1000.0


@dataclass(frozen=True)
class FrameFiles:
    """What was written for keyframe ``k``: paths relative to the export folder (None: not written)."""

    k: int
    image: str
    mask: str | None
    depth: str | None


def _write_png(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"cannot encode {path.name} as PNG")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data.tobytes())


def depth_png(depth_m: np.ndarray) -> np.ndarray:
    """Metres (0 invalid) → uint16 millimetres; invalid, non-finite or beyond the 16-bit range → 0."""
    mm = np.rint(np.nan_to_num(depth_m, nan=0.0, posinf=0.0, neginf=0.0) * DEPTH_UNITS_PER_METRE)
    return np.where((mm > 0) & (mm <= 65535), mm, 0).astype(np.uint16)


def write_frame_files(run: TrainerRun, source, folder: Path, mask_path: Callable[[str], str], dilate: int,
                      with_depth: bool, progress: bool = False) -> list[FrameFiles]:
    """Write every keyframe's image, mask and (``with_depth``) depth into ``folder``; see the module docstring.

    ``mask_path(NAME)`` gives a mask's path relative to ``folder`` (layouts differ).  The sensor depth of
    the first keyframe that has any is checked against the run's own depth (:func:`check_depth_scale`).
    """
    lookup = None
    if run.masks is not None:
        lookup = grid_lookup(run.calibration, run.size, run.work_intrinsics, run.masks.shape[1:])
    written: list[FrameFiles] = []
    checked = False
    for k, image, depth in keyframe_frames(run, source, progress):
        name = frame_name(run.index[k])
        _write_png(folder / "images" / name, cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
        mask_rel = None
        if lookup is not None:
            mask_rel = mask_path(name)
            _write_png(folder / mask_rel, mask_image(lookup.upsample(run.masks[k]), dilate))
        depth_rel = None
        if with_depth and depth is not None and bool((depth > 0).any()):
            if not checked:
                check_depth_scale(run, k, depth)
                checked = True
            depth_rel = f"depths/{name}"
            _write_png(folder / depth_rel, depth_png(depth))
        written.append(FrameFiles(k, f"images/{name}", mask_rel, depth_rel))
    return written
