"""``droidw export nerfstudio``: a run as a nerfstudio dataset (``transforms.json``) for 3DGS / NeRF trainers.

The folder::

    transforms.json
    images/frame_NNNNNN.png    every keyframe, input resolution
    masks/frame_NNNNNN.png     0 = ignore (the movers), 255 = static (runs with masks)
    depths/frame_NNNNNN.png    sensor z-depth, uint16 millimetres (RGB-D runs: run.json metric)
    points.ply                 the static point cloud of `export ply --what static` (splatfacto's start)

``transforms.json`` holds the camera once (``camera_model`` PINHOLE, or OPENCV
with ``k1 k2 p1 p2`` [``k3``] when the calibration has distortion; ``fl_x fl_y
cx cy w h`` in nerfstudio's pixel convention, a pixel's centre at +½, so
``cx`` = calib.txt's cx + ½) and one entry per keyframe: ``file_path``,
``transform_matrix`` and, where written, ``mask_path`` / ``depth_file_path``.

``transform_matrix`` is camera-to-world in nerfstudio's (OpenGL / Blender)
camera axes, x right, y up, z back: the run's OpenCV camera-to-world pose
(x right, y down, z forward) times diag(1, −1, −1, 1) on the camera side, in
the run's world frame (that of ``traj.txt``; nerfstudio re-orients and
re-centres it itself, points and cameras alike).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from droidw_cli.export.pointcloud import CloudParams, build_cloud, write_ply
from droidw_cli.export.staging import check_export_folder, staged_folder
from droidw_cli.export.trainer_files import DEPTH_UNITS_PER_METRE, FrameFiles, write_frame_files
from droidw_cli.export.trainer_masks import default_dilation
from droidw_cli.export.trainer_run import TrainerRun, load_trainer_run, open_frames, trainer_intrinsics
from droidw_cli.io.trajectory import atomic_write_text

#: OpenCV camera axes → OpenGL camera axes (right-multiplied onto a camera-to-world matrix)
OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


def opengl_c2w(poses_c2w_opencv: np.ndarray) -> np.ndarray:
    """(…, 4, 4) OpenCV-axes camera-to-world → OpenGL-axes camera-to-world (same camera centre, y and z flipped)."""
    return np.asarray(poses_c2w_opencv, dtype=np.float64) @ OPENCV_TO_OPENGL


def camera_fields(run: TrainerRun) -> dict:
    """The intrinsics part of ``transforms.json`` (module docstring)."""
    fx, fy, cx, cy = trainer_intrinsics(run.calibration)
    h, w = run.size
    fields = {"camera_model": "OPENCV" if run.calibration.has_distortion else "PINHOLE",
              "fl_x": fx, "fl_y": fy, "cx": cx, "cy": cy, "w": int(w), "h": int(h)}
    if run.calibration.has_distortion:
        fields.update(zip(("k1", "k2", "p1", "p2", "k3"), (float(v) for v in run.calibration.distortion)))
    return fields


def transforms_json(run: TrainerRun, files: list[FrameFiles], ply: str | None, dilate: int) -> dict:
    """The ``transforms.json`` document for the written ``files``."""
    doc = camera_fields(run)
    if any(f.depth for f in files):
        doc["depth_unit_scale_factor"] = 1.0 / DEPTH_UNITS_PER_METRE
    if ply:
        doc["ply_file_path"] = ply
    c2w = opengl_c2w(run.poses_c2w)
    frames = []
    for f in files:
        entry = {"file_path": f.image, "transform_matrix": c2w[f.k].tolist()}
        if f.mask:
            entry["mask_path"] = f.mask
        if f.depth:
            entry["depth_file_path"] = f.depth
        frames.append(entry)
    doc["frames"] = frames
    doc["droidw"] = {"run": str(run.run_dir), "input": run.input, "keyframes": run.num_keyframes,
                     "frame_index": [int(run.index[f.k]) for f in files],
                     "timestamps": [float(run.timestamps[f.k]) for f in files],
                     "masks": run.mask_kind, "mask_dilate_px": int(dilate), "metric": run.metric,
                     "transform_matrix": "camera-to-world, OpenGL camera axes (x right, y up, z back)"}
    return doc


def export_nerfstudio(run_dir: Path, out: Path, *, input_path=None, masks: str = "dynamic", dilate: int | None = None,
                      depth_scale: float = 5000.0, cloud: CloudParams = CloudParams(),
                      progress: bool = False) -> dict:
    """Write the folder of the module docstring into ``out`` (all or nothing); returns ``transforms.json``.

    ``depth_scale``: the depth images' units per metre, as ``droidw track --depth-scale`` (RGB-D runs only).
    """
    check_export_folder(out)
    run = load_trainer_run(run_dir, masks)
    static = build_cloud(run.npz, cloud).part("static")
    run, source = open_frames(run, input_path, depth_scale if run.metric else None)
    dilate = default_dilation(run.calibration, run.work_intrinsics) if dilate is None else int(dilate)
    with staged_folder(out) as tmp:
        files = write_frame_files(run, source, tmp, lambda name: f"masks/{name}", dilate, run.metric, progress)
        ply = None
        if len(static.xyz):
            write_ply(tmp / "points.ply", static, with_time=False)
            ply = "points.ply"
        doc = transforms_json(run, files, ply, dilate)
        atomic_write_text(tmp / "transforms.json", json.dumps(doc, indent=2) + "\n")
    return doc
