"""A tracked run as a 3D Gaussian-splatting trainer needs it: the camera, the keyframe poses and frames.

Used by ``droidw export nerfstudio`` and ``droidw export colmap``.  What is read:

* ``keyframes.npz``: ``poses_c2w`` (camera-to-world, OpenCV camera axes x right, y down, z forward, in the
  run's world frame), ``index`` (each keyframe's position in the run's frame selection), ``timestamps``,
  ``intrinsics`` / ``work_size`` (the working image the run tracked on) and the 1/8-grid masks;
* ``calib.txt``: the camera of the *input* frames, OpenCV's pixel convention (a pixel's centre at integer
  coordinates); the radial-tangential distortion the run removed before tracking (if any) is taken from
  calib.txt, else from the calibration the run used (:func:`_with_distortion`);
* ``run.json``: ``input`` (re-read with :func:`~droidw_cli.io.input.open_source` with the run's frame
  selection, ``config.io``), ``metric``.

Frames are exported at the input resolution, as the input holds them (distorted where the calibration has
distortion, so the trainer's camera model carries it).  Trainers put a pixel's centre at +½ (COLMAP,
nerfstudio, gsplat), so their principal point is the OpenCV one + ½: :func:`trainer_intrinsics`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from droidw_cli.errors import InputError, UserError
from droidw_cli.export.run_files import load_run
from droidw_cli.geometry.camera import working_size
from droidw_cli.io.calibration import Calibration, load_calibration

#: sensor depth / the run's depth outside this band means the depth images are read at the wrong scale
DEPTH_RATIO_BAND = (0.5, 2.0)
#: timestamps of a re-read frame and its keyframe may differ by this much (seconds) before the input counts as changed
TIME_TOLERANCE = 1e-4
#: calib.txt brought to the working size may differ from the run's working intrinsics by this × fx
INTRINSICS_TOLERANCE = 1e-4


@dataclass(frozen=True)
class TrainerRun:
    """The parts of a run folder an export for a trainer uses.

    ``calibration`` is at the input size ``size`` = (H, W), OpenCV pixel convention; ``work_intrinsics``
    (fx fy cx cy) at the working size; ``poses_c2w`` (K, 4, 4) camera-to-world with OpenCV camera axes;
    ``masks`` (K, h, w) bool on the 1/8 BA grid, True = a mover to ignore (None: the run has no masks);
    ``io``: the run's ``config.io`` (frame selection, target area).  ``size`` is (0, 0) until
    :func:`open_frames` has opened the input.
    """

    run_dir: Path
    input: str
    calibration: Calibration
    size: tuple[int, int]
    work_intrinsics: np.ndarray
    index: np.ndarray
    timestamps: np.ndarray
    poses_c2w: np.ndarray
    masks: np.ndarray | None
    mask_kind: str | None
    metric: bool
    io: dict
    npz: dict
    calibration_source: str = ""

    @property
    def num_keyframes(self) -> int:
        return int(len(self.index))


def trainer_intrinsics(calib: Calibration) -> tuple[float, float, float, float]:
    """``fx, fy, cx, cy`` in the trainers' pixel convention (a pixel's centre at +½): OpenCV's cx, cy + ½."""
    return float(calib.fx), float(calib.fy), float(calib.cx) + 0.5, float(calib.cy) + 0.5


def frame_name(index: int) -> str:
    """The exported image's file name of the frame at selection position ``index``."""
    return f"frame_{int(index):06d}.png"


def _read_info(run_dir: Path) -> dict:
    path = run_dir / "run.json"
    try:
        info = json.loads(path.read_text())
    except OSError:
        raise InputError(f"{path}: no such file; the run folder is incomplete (run `droidw track` again)") from None
    except ValueError as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(info, dict) or "input" not in info:
        raise InputError(f"{path}: no 'input' entry; cannot find the frames the run tracked")
    return info


def load_trainer_run(run_dir: Path, masks: str = "dynamic") -> TrainerRun:
    """Read a run folder (clear :class:`InputError` for a missing folder, file, keyframes or calibration).

    ``masks``: ``dynamic`` (the run's output masks; the default) or ``masked`` (those joined with every
    pixel BA zeroed in the loop, the set the static point cloud leaves out); a run without ``masked``
    falls back to ``dynamic``.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise InputError(f"{run_dir}: no such run folder; run `droidw track ... --out {run_dir}` first")
    npz = load_run(run_dir)
    info = _read_info(run_dir)
    poses = np.asarray(npz.get("poses_c2w", np.zeros((0, 4, 4))), dtype=np.float64)
    if len(poses) == 0 or "index" not in npz:
        raise InputError(f"{run_dir}: the run has no keyframes (no poses to export)")
    calib_path = run_dir / "calib.txt"
    if not calib_path.is_file():
        raise InputError(f"{calib_path}: no such file; the run folder is incomplete")
    calib = load_calibration(calib_path)
    kind = masks if masks in npz else ("dynamic" if "dynamic" in npz else None)
    return TrainerRun(
        run_dir=run_dir, input=str(info["input"]), calibration=calib, size=(0, 0),
        work_intrinsics=np.asarray(npz["intrinsics"], dtype=np.float64), index=np.asarray(npz["index"], np.int64),
        timestamps=np.asarray(npz["timestamps"], np.float64), poses_c2w=poses,
        masks=None if kind is None else np.asarray(npz[kind], dtype=bool), mask_kind=kind,
        metric=bool(info.get("metric", False)), io=dict((info.get("config") or {}).get("io") or {}), npz=npz,
        calibration_source=str((info.get("calibration") or {}).get("source", "")),
    )


def _with_distortion(run: TrainerRun, source) -> Calibration:
    """calib.txt's camera with the distortion the run removed from the frames.

    A run's calib.txt holds the intrinsics without the distortion (the tracker undistorted the frames
    and records the result), so the distortion comes from where the calibration came from (``run.json``
    ``calibration.source``): the calibration found with the input, or the ``--calib`` file, if it still
    reads and its fx fy cx cy are calib.txt's.
    """
    calib = run.calibration
    if calib.has_distortion or run.calibration_source in ("", "estimated", "guessed", "auto"):
        return calib
    origin = source.intrinsics_hint
    if run.calibration_source != "input":
        try:
            origin = load_calibration(run.calibration_source, source.size, camera=source.calibration_camera)
        except UserError:
            origin = None
    if origin is None or not origin.has_distortion:
        return calib
    if np.abs(origin.as_array() - calib.as_array()).max() > INTRINSICS_TOLERANCE * calib.fx:
        return calib  # not the camera the run used
    return Calibration(calib.fx, calib.fy, calib.cx, calib.cy, tuple(origin.distortion))


def open_frames(run: TrainerRun, input_path: str | Path | None = None, depth_scale: float | None = None):
    """Open the run's input (``input_path`` overrides ``run.json``'s) with its frame selection.

    Returns ``(run, source)`` where ``run`` now knows the input size.  Raises :class:`InputError` when the
    input is gone or its frames are not the size the run tracked.  ``depth_scale`` (depth PNG units per
    metre): read the sensor depth too (only sources with depth images).
    """
    from dataclasses import replace

    from droidw_cli.io.input import open_source

    io = run.io
    path = Path(input_path) if input_path is not None else Path(run.input)
    try:
        source = open_source(path, stride=int(io.get("stride", 1)), start=int(io.get("start", 0)),
                             max_frames=int(io.get("max_frames", 0)), fps=float(io.get("fps", 30.0)),
                             strict_calibration=False)
    except UserError as exc:
        hint = "" if input_path is not None else " (pass --input PATH if the frames moved)"
        raise InputError(f"cannot read the frames of {run.run_dir}: {exc}{hint}") from None
    h, w = source.size
    work = tuple(int(v) for v in run.npz["work_size"])
    expected = working_size(h, w, int(io.get("target_area", 384 * 512)))[1]
    if expected != work:
        raise InputError(f"{path}: its frames are {w}x{h}, which do not give the run's working size "
                         f"{work[1]}x{work[0]}: not the input {run.run_dir} was tracked on")
    run.calibration.validate(source.size, f"{run.run_dir / 'calib.txt'}")
    prepared = run.calibration.prepared(source.size, int(io.get("target_area", 384 * 512))).as_array()
    if np.abs(prepared - run.work_intrinsics).max() > INTRINSICS_TOLERANCE * run.work_intrinsics[0]:
        raise InputError(f"{run.run_dir / 'calib.txt'} does not give the run's working intrinsics "
                         f"{np.round(run.work_intrinsics, 3).tolist()} at {w}x{h} (got {np.round(prepared, 3).tolist()})")
    if hasattr(source, "load_depth"):
        source.load_depth = depth_scale is not None and bool(getattr(source, "has_depth", False))
        if depth_scale is not None:
            source.depth_scale = float(depth_scale)
            source.lazy_depth = True  # only the keyframes' depth images are decoded
    return replace(run, size=(int(h), int(w)), calibration=_with_distortion(run, source)), source


def keyframe_frames(run: TrainerRun, source, progress: bool = False) -> Iterator[tuple[int, np.ndarray, np.ndarray | None]]:
    """``(k, image, depth)`` for every keyframe k in order: the input frame (H×W×3 uint8 RGB) and its sensor
    depth (H×W float32 metres, 0 invalid; None without).  Stops reading once the last keyframe is found.

    Raises :class:`InputError` when a keyframe's frame is missing, unreadable or has another timestamp
    (the input changed since the run).
    """
    from tqdm import tqdm

    wanted = {int(i): k for k, i in enumerate(run.index)}
    seen: set[int] = set()
    with tqdm(total=len(wanted), desc="frames", unit="kf", disable=not progress, leave=False) as bar:
        for frame in source:
            k = wanted.get(int(frame.index))
            if k is None:
                continue
            if abs(frame.timestamp - run.timestamps[k]) > TIME_TOLERANCE * max(1.0, abs(run.timestamps[k])):
                raise InputError(f"{source.path}: frame {frame.index} has timestamp {frame.timestamp:.6f}, the run's "
                                 f"keyframe {k} has {run.timestamps[k]:.6f}: not the input the run was tracked on")
            depth = frame.depth() if callable(frame.depth) else frame.depth
            yield k, frame.image, depth
            seen.add(k)
            bar.update()
            if len(seen) == len(wanted):
                return
    missing = min(i for i, k in wanted.items() if k not in seen)
    raise InputError(f"{source.path}: frame {missing} (a keyframe of {run.run_dir}) is missing or cannot be "
                     f"decoded; {len(seen)} of {len(wanted)} keyframes were found")


def check_depth_scale(run: TrainerRun, k: int, depth: np.ndarray) -> float:
    """The median ratio of the sensor depth of keyframe ``k`` to the run's own (metric) depth on the BA grid.

    Raises :class:`InputError` outside :data:`DEPTH_RATIO_BAND`: the depth images are then read at the wrong
    scale (``--depth-scale``) and would teach a trainer the wrong geometry.  Distortion is ignored here (a
    check of the scale, not of pixels).
    """
    disps = np.asarray(run.npz["disps"][k], dtype=np.float64)
    gh, gw = disps.shape
    fxw, fyw, cxw, cyw = run.work_intrinsics
    fx, fy, cx, cy = run.calibration.as_array()
    gy, gx = np.mgrid[0:gh, 0:gw].astype(np.float64)
    u = np.rint(cx + fx * ((8 * gx + 3.5) - cxw) / fxw).astype(int)  # each cell's centre in input pixels
    v = np.rint(cy + fy * ((8 * gy + 3.5) - cyw) / fyw).astype(int)
    inside = (u >= 0) & (u < depth.shape[1]) & (v >= 0) & (v < depth.shape[0]) & (disps > 1e-6)
    sensor = depth[v[inside], u[inside]]
    ok = sensor > 0
    if not ok.any():
        return float("nan")
    ratio = float(np.median(sensor[ok] * disps[inside][ok]))
    lo, hi = DEPTH_RATIO_BAND
    if not lo <= ratio <= hi:
        raise InputError(f"the sensor depth of keyframe {k} is {ratio:.3g} × the run's metric depth: the depth "
                         f"images are read at the wrong scale; pass the --depth-scale the run was tracked with "
                         f"(5000: TUM, Bonn; 1000: millimetres)")
    return ratio
