"""Logging a ``droidw track`` run to rerun (``pip install 'droidw[view]'``).

Entities (world = the run's camera-to-world frame, OpenCV axes: x right,
y down, z forward):

* ``world/trajectory``: the camera path through every frame (static);
* ``world/keyframes``: one frustum per keyframe (static);
* ``world/points/static``: the static cloud, as ``droidw export ply`` builds it (static);
* ``world/points/dynamic``: each keyframe's dynamic points, at its time;
* ``world/camera``: the camera pose at every frame, and ``world/camera/image``
  its pinhole and keyframe image;
* ``uncertainty``: the keyframe with its uncertainty u blended over it (inferno:
  dark = low, bright = high), and ``stats/mean_uncertainty``;
* ``run``: a text summary of ``run.json``;
* with a ``droidw map`` folder, its Gaussians (:mod:`droidw_cli.export.rrd_map`).

Timelines: ``frame`` (the input frame index) and ``time`` (seconds since the
first frame).
"""

from __future__ import annotations

import json
import os
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from droidw_cli.errors import InputError, UserError

INSTALL_HINT = "pip install 'droidw[view]'"
DYNAMIC_COLOUR = (255, 64, 160)
TRAJECTORY_COLOUR = (80, 160, 255)
FRUSTUM_COLOUR = (255, 200, 40)


def require_rerun():
    try:
        import rerun
    except ImportError:
        raise UserError(f"droidw view needs rerun, which is not installed: {INSTALL_HINT}") from None
    return rerun


@dataclass(frozen=True)
class Run:
    """What ``droidw track`` wrote: keyframe arrays, the per-frame trajectory and run.json."""

    folder: Path
    npz: dict
    timestamps: np.ndarray  # (N,) every frame
    poses_c2w: np.ndarray  # (N, 4, 4)
    info: dict


def load_run_folder(folder: Path) -> Run:
    from droidw_cli.export.run_files import load_run
    from droidw_cli.io.trajectory import read_trajectory

    if not folder.is_dir():
        raise InputError(f"{folder}: not a run folder (run `droidw track ... --out {folder}` first)")
    npz = load_run(folder)
    missing = [k for k in ("index", "timestamps", "poses_c2w", "disps", "intrinsics", "work_size", "images")
               if k not in npz]
    if missing:
        raise InputError(f"{folder / 'keyframes.npz'}: missing {', '.join(missing)}")
    if (folder / "traj.txt").is_file():
        traj = read_trajectory(folder / "traj.txt")
        stamps, poses = traj.timestamps, traj.poses
    else:  # keyframes only
        stamps, poses = np.asarray(npz["timestamps"], np.float64), np.asarray(npz["poses_c2w"], np.float64)
    info = {}
    if (folder / "run.json").is_file():
        try:
            info = json.loads((folder / "run.json").read_text())
        except ValueError as exc:
            raise InputError(f"{folder / 'run.json'}: not valid JSON ({exc})") from None
    return Run(folder, npz, stamps, poses, info)


def frustum_strips(poses_c2w: np.ndarray, intrinsics: np.ndarray, size_hw, depth: float) -> list[np.ndarray]:
    """Line strips (5 per camera) of image-shaped pyramids ``depth`` deep, in world coordinates."""
    fx, fy, cx, cy = (float(v) for v in intrinsics[:4])
    h, w = size_hw
    corners = np.array([[(u - cx) / fx * depth, (v - cy) / fy * depth, depth]
                        for u, v in ((0, 0), (w, 0), (w, h), (0, h))])
    strips = []
    for pose in poses_c2w:
        c = corners @ pose[:3, :3].T + pose[:3, 3]
        o = pose[:3, 3]
        strips.append(np.vstack([c, c[:1]]))
        strips += [np.vstack([o, c[k]]) for k in range(4)]
    return strips


def _summary_text(run: Run) -> str:
    info = run.info
    lines = [f"# droidw run `{run.folder}`", ""]
    for key, label in (("input", "input"), ("frames", "frames"), ("keyframes", "keyframes"), ("fps", "frames/s"),
                       ("backend", "backend"), ("initialised", "initialised")):
        if key in info:
            lines.append(f"* {label}: {info[key]}")
    for w in info.get("warnings", []):
        lines.append(f"* warning: {w}")
    return "\n".join(lines) + "\n"


def log_run(rec, run: Run, progress: bool = False, stride: int = 1) -> dict:
    """Log ``run`` into the recording stream ``rec``; returns counts of what was logged."""
    import rerun as rr
    from tqdm import tqdm

    from droidw_cli.export.overlay import blend, uncertainty_range
    from droidw_cli.export.pointcloud import CloudParams, build_cloud

    npz = run.npz
    kf_index = np.asarray(npz["index"], dtype=np.int64)
    kf_poses = np.asarray(npz["poses_c2w"], dtype=np.float64)
    disps = np.asarray(npz["disps"], dtype=np.float32)
    images = np.asarray(npz["images"])
    work_h, work_w = (int(v) for v in np.asarray(npz["work_size"])[:2])
    k_work = np.asarray(npz["intrinsics"], dtype=np.float64)
    unc = np.asarray(npz["uncertainty"], dtype=np.float32) if "uncertainty" in npz else None
    t0 = float(run.timestamps[0]) if len(run.timestamps) else 0.0
    valid = disps[disps > 1e-6]
    depth = 0.15 * float(np.median(1.0 / valid)) if valid.size else 0.1

    rec.log("world", rr.ViewCoordinates.RDF, static=True)
    rec.log("run", rr.TextDocument(_summary_text(run), media_type=rr.MediaType.MARKDOWN), static=True)
    rec.log("world/trajectory", rr.LineStrips3D([run.poses_c2w[:, :3, 3]], colors=[TRAJECTORY_COLOUR]), static=True)
    rec.log("world/keyframes", rr.LineStrips3D(frustum_strips(kf_poses, k_work, (work_h, work_w), depth),
                                              colors=[FRUSTUM_COLOUR]), static=True)
    try:
        cloud = build_cloud(npz, CloudParams(stride=stride))
        note = None
    except InputError:  # too few keyframes for a multi-view map (a fixed camera): show the rest
        n = len(disps)
        cloud, note = None, (f"no point cloud: the run has {n} keyframe{'s' if n != 1 else ''}, too few for a "
                             f"multi-view map (a camera that barely moves keeps one); the trajectory and images "
                             f"are shown")
        rec.log("run/note", rr.TextDocument(note), static=True)
    static_points = 0
    if cloud is not None:
        static = cloud.part("static")
        static_points = len(static.xyz)
        rec.log("world/points/static", rr.Points3D(static.xyz, colors=static.rgb, radii=[-1.5]), static=True)

    th, tw = images.shape[1:3]
    sx, sy = tw / work_w, th / work_h
    k_img = np.array([[k_work[0] * sx, 0, k_work[2] * sx], [0, k_work[1] * sy, k_work[3] * sy], [0, 0, 1]])
    rec.log("world/camera/image", rr.Pinhole(image_from_camera=k_img, resolution=[tw, th],
                                             image_plane_distance=depth), static=True)

    def at(frame: int, stamp: float) -> None:
        rec.set_time("frame", sequence=int(frame))
        rec.set_time("time", duration=float(stamp) - t0)

    for i, pose in enumerate(tqdm(run.poses_c2w, desc="poses", unit="frame", disable=not progress, leave=False)):
        at(i, run.timestamps[i])
        rec.log("world/camera", rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))

    lo, hi = uncertainty_range(unc) if unc is not None else (0.0, 1.0)
    kf_times = np.asarray(npz["timestamps"], dtype=np.float64)
    dynamic_total = 0
    for k in tqdm(range(len(kf_index)), desc="keyframes", unit="kf", disable=not progress, leave=False):
        at(kf_index[k], kf_times[k])
        rec.log("world/camera/image", rr.Image(images[k]))
        if cloud is not None:
            dyn = cloud.dynamic & (cloud.time == kf_times[k])
            rec.log("world/points/dynamic", rr.Points3D(cloud.xyz[dyn], colors=[DYNAMIC_COLOUR], radii=[-2.0]))
            dynamic_total += int(dyn.sum())
        if unc is not None:
            rec.log("uncertainty", rr.Image(cv2.cvtColor(blend(images[k], unc[k], lo, hi), cv2.COLOR_BGR2RGB)))
            rec.log("stats/mean_uncertainty", rr.Scalars(float(np.mean(unc[k]))))
    return {"frames": int(len(run.poses_c2w)), "keyframes": int(len(kf_index)),
            "static_points": int(static_points), "dynamic_points": dynamic_total, "note": note}


def _log_map(rec, run: Run, map_dir: Path | None, counts: dict) -> None:
    if map_dir is None:
        return
    from droidw_cli.export.rrd_map import log_map

    t0 = float(run.timestamps[0]) if len(run.timestamps) else 0.0
    counts["gaussians"] = log_map(rec, map_dir, t0, np.asarray(run.npz["timestamps"], dtype=np.float64),
                                  np.asarray(run.npz["index"], dtype=np.int64))


def save_rrd(run: Run, path: Path, progress: bool = False, stride: int = 1, map_dir: Path | None = None) -> dict:
    """Write ``run`` to an .rrd file atomically (no viewer, works headless); returns the counts."""
    rr = require_rerun()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.parent / f".{path.name}.{os.getpid()}.tmp"
    rec = rr.RecordingStream("droidw")
    try:
        rec.save(str(tmp))
        counts = log_run(rec, run, progress, stride)
        _log_map(rec, run, map_dir, counts)
        rec.flush()
        rec.disconnect()
        os.replace(tmp, path)
        return counts
    finally:
        if tmp.exists():
            tmp.unlink()


def show(run: Run, progress: bool = False, stride: int = 1, map_dir: Path | None = None) -> dict:
    """Spawn a rerun viewer and log ``run`` into it."""
    rr = require_rerun()
    headless = not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    if sys.platform.startswith("linux") and headless:
        raise UserError("no display to open the rerun viewer on: write a file with --save run.rrd "
                        "and open it with `rerun run.rrd` where there is one")
    rec = rr.RecordingStream("droidw")
    rec.spawn()
    counts = log_run(rec, run, progress, stride)
    _log_map(rec, run, map_dir, counts)
    rec.flush()
    return counts
