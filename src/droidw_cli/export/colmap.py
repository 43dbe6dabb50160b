"""``droidw export colmap``: a run as a COLMAP text model, for gsplat's and the original 3DGS trainers.

The folder::

    sparse/0/cameras.txt      one camera: PINHOLE fx fy cx cy, or OPENCV fx fy cx cy k1 k2 p1 p2
                              (FULL_OPENCV with k3), at the input image size
    sparse/0/images.txt       per keyframe: IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, then its 2D points
    sparse/0/points3D.txt     the static points: POINT3D_ID X Y Z R G B ERROR TRACK[]
    images/frame_NNNNNN.png   every keyframe, input resolution
    masks/frame_NNNNNN.png.png  COLMAP's mask convention (masks/NAME.png): 0 = ignore (movers), 255 = static

COLMAP's conventions: the pose of an image is **world-to-camera**, x_cam =
R·X + t, R as the unit quaternion (QW QX QY QZ, Hamilton, QW ≥ 0 here), in
OpenCV camera axes (x right, y down, z forward); the camera centre is −Rᵀt.
Pixel coordinates put a pixel's centre at +½, so cx, cy and the 2D points are
OpenCV's + ½.

The static points are those of ``export ply --what static``, in the run's
world frame (that of ``traj.txt``), colour from the keyframe thumbnails.  Each
has a track of length one: the keyframe whose depth it came from, where its
2D point is its projection (with the distortion); ERROR is 0.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from droidw_cli.export.pointcloud import Cloud, CloudParams, build_cloud
from droidw_cli.export.staging import check_export_folder, staged_folder
from droidw_cli.export.trainer_files import FrameFiles, write_frame_files
from droidw_cli.export.trainer_masks import default_dilation
from droidw_cli.export.trainer_run import TrainerRun, load_trainer_run, open_frames, trainer_intrinsics
from droidw_cli.io.trajectory import atomic_write_text, matrix_to_quat_xyzw


def camera_line(run: TrainerRun) -> str:
    """The one data line of ``cameras.txt`` (camera 1)."""
    fx, fy, cx, cy = trainer_intrinsics(run.calibration)
    h, w = run.size
    dist = [float(v) for v in run.calibration.distortion]
    if not run.calibration.has_distortion:
        model, params = "PINHOLE", [fx, fy, cx, cy]
    elif len(dist) == 5 and dist[4] != 0.0:
        model, params = "FULL_OPENCV", [fx, fy, cx, cy, *dist, 0.0, 0.0, 0.0]  # k1 k2 p1 p2 k3 k4 k5 k6
    else:
        model, params = "OPENCV", [fx, fy, cx, cy, *dist[:4]]
    return f"1 {model} {w} {h} " + " ".join(repr(p) for p in params)


def world_to_camera(pose_c2w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """COLMAP's (quaternion w x y z with w ≥ 0, translation t) of an OpenCV camera-to-world pose."""
    r = pose_c2w[:3, :3].T
    t = -r @ pose_c2w[:3, 3]
    x, y, z, w = matrix_to_quat_xyzw(r)
    q = np.array([w, x, y, z], dtype=np.float64)
    return (q if q[0] >= 0 else -q), t


def observations(run: TrainerRun, points: Cloud) -> tuple[np.ndarray, np.ndarray]:
    """Each static point's keyframe (by its keyframe time) and its 2D point there, (P,) and (P, 2) COLMAP pixels."""
    order = np.argsort(run.timestamps)
    pos = np.clip(np.searchsorted(run.timestamps[order], points.time), 0, len(order) - 1)
    kf = order[pos]
    if len(kf) and not np.array_equal(run.timestamps[kf], points.time):
        raise ValueError("a static point's time matches no keyframe")
    uv = np.zeros((len(kf), 2))
    k_cv = run.calibration.camera_matrix()
    dist = np.asarray(run.calibration.distortion or (0.0, 0.0, 0.0, 0.0), dtype=np.float64)
    for k in np.unique(kf):  # one projection call per keyframe
        sel = kf == k
        w2c = np.linalg.inv(run.poses_c2w[k])
        cam = points.xyz[sel].astype(np.float64) @ w2c[:3, :3].T + w2c[:3, 3]
        proj, _ = cv2.projectPoints(cam.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), k_cv, dist)
        uv[sel] = proj.reshape(-1, 2) + 0.5
    return kf, uv


def _fmt_rows(values: np.ndarray, fmt: str) -> list[str]:
    return [fmt % tuple(row) for row in values]


def model_texts(run: TrainerRun, files: list[FrameFiles], points: Cloud) -> dict[str, str]:
    """``cameras.txt``, ``images.txt`` and ``points3D.txt`` as text (module docstring)."""
    kf, uv = observations(run, points)
    image_id = {f.k: i + 1 for i, f in enumerate(files)}
    point_idx = np.zeros(len(kf), dtype=np.int64)  # each point's index among its image's 2D points
    cameras = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
               "# Number of cameras: 1", camera_line(run)]
    images = ["# Image list with two lines of data per image:",
              "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME", "#   POINTS2D[] as (X, Y, POINT3D_ID)",
              f"# Number of images: {len(files)}, mean observations per image: {len(kf) / max(1, len(files)):g}"]
    for f in files:
        q, t = world_to_camera(run.poses_c2w[f.k])
        images.append(f"{image_id[f.k]} " + " ".join(repr(float(v)) for v in (*q, *t)) + f" 1 {Path(f.image).name}")
        sel = np.flatnonzero(kf == f.k)
        point_idx[sel] = np.arange(len(sel))
        rows = np.column_stack([uv[sel], sel + 1]) if len(sel) else np.zeros((0, 3))
        images.append(" ".join(_fmt_rows(rows, "%.3f %.3f %d")))
    points3d = ["# 3D point list with one line of data per point:",
                "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
                f"# Number of points: {len(kf)}, mean track length: {1 if len(kf) else 0}"]
    if len(kf):
        img = np.array([image_id.get(int(k), 0) for k in range(run.num_keyframes)])[kf]
        table = np.column_stack([np.arange(1, len(kf) + 1), points.xyz.astype(np.float64), points.rgb, img, point_idx])
        points3d += _fmt_rows(table, "%d %.6f %.6f %.6f %d %d %d 0 %d %d")
    return {name: "\n".join(lines) + "\n" for name, lines in
            (("cameras.txt", cameras), ("images.txt", images), ("points3D.txt", points3d))}


def export_colmap(run_dir: Path, out: Path, *, input_path=None, masks: str = "dynamic", dilate: int | None = None,
                  cloud: CloudParams = CloudParams(), progress: bool = False) -> dict:
    """Write the folder of the module docstring into ``out`` (all or nothing); returns a summary."""
    check_export_folder(out)
    run = load_trainer_run(run_dir, masks)
    static = build_cloud(run.npz, cloud).part("static")
    run, source = open_frames(run, input_path)
    dilate = default_dilation(run.calibration, run.work_intrinsics) if dilate is None else int(dilate)
    with staged_folder(out) as tmp:
        files = write_frame_files(run, source, tmp, lambda name: f"masks/{name}.png", dilate, False, progress)
        for name, text in model_texts(run, files, static).items():
            atomic_write_text(tmp / "sparse" / "0" / name, text)
    return {"images": len(files), "points": int(len(static.xyz)), "masks": sum(f.mask is not None for f in files),
            "camera": camera_line(run).split()[1], "mask_dilate_px": dilate}
