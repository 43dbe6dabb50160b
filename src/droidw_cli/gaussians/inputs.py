"""What ``droidw map`` fits and evaluates: a tracked run's keyframes and held-out frames at the map's size.

From the run folder (docs/formats.md): ``keyframes.npz`` (poses, inverse depth on the 1/8 grid, the working
intrinsics, the dynamic masks and object ids), ``traj.txt`` (every frame's pose), ``calib.txt`` and
``run.json`` (the input and its frame selection).  The input's frames are read again at full resolution and
prepared exactly as the tracker prepared them (:class:`~droidw_cli.io.prepare.FramePreparer`: undistort,
resize, centre-crop to the working size), then area-averaged to the map's size (H, W), whose intrinsics
follow from the pixel-centre convention: f' = f s, c' = (c + ½) s − ½.

Depth targets: monocular runs use the run's own inverse depth (bilinear on the grid, d = 1 / disparity, in
the run's scale); RGB-D runs the sensor's depth (nearest neighbour; the run's depth where the sensor has
none).  Static pixels: not in the keyframe's ``dynamic`` mask grown by ``mask_dilate`` grid cells.  Held-out
frames: every ``holdout_every``-th non-keyframe, with the input's ground-truth dynamic masks when it has them
(a ``mask.txt`` listing, as ``droidw synth`` writes), else the nearest keyframe's mask.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.gaussians.params import MapParams


@dataclass
class Views:
    """V frames at the map's size: ``index`` (input frame), ``timestamps``, ``poses`` c2w (V, 4, 4),
    ``images`` (V, H, W, 3) float32 in [0, 1]; for keyframes also ``depth`` (V, H, W) (0 = none),
    ``static`` (V, H, W) bool and ``object_ids`` (V, H, W) int32 (−1 none); for held-out frames ``dynamic``
    (V, H, W) bool (the mask their scores are split by)."""

    index: np.ndarray
    timestamps: np.ndarray
    poses: np.ndarray
    images: np.ndarray
    depth: np.ndarray | None = None
    static: np.ndarray | None = None
    object_ids: np.ndarray | None = None
    dynamic: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.index)


@dataclass
class MapInputs:
    """The keyframes and the held-out views, the map's ``size`` (H, W) and ``intrinsics``, and about the run:
    ``metric`` (RGB-D), ``has_masks``, ``mask_source`` (of the held-out masks), ``input`` (path)."""

    keyframes: Views
    heldout: Views
    size: tuple[int, int]
    intrinsics: tuple[float, float, float, float]
    metric: bool
    has_masks: bool
    mask_source: str
    input: str


def _read_json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path}: cannot read the run's settings ({exc}); is this a `droidw track` folder?") from None


def check_multiview(npz: dict, run_dir: Path) -> None:
    """A map needs the camera to have moved: two keyframes at least, and not every pose the first."""
    poses = npz["poses_c2w"]
    if len(poses) < 2 or bool(np.allclose(poses, poses[:1], atol=1e-9)):
        raise InputError(f"{run_dir}: the camera never moved in this run (a fixed camera, {len(poses)} distinct "
                         f"keyframe pose{'s' if len(poses) != 1 else ''}), so there is no multi-view map to fit")


def map_size(work_size: tuple[int, int], params: MapParams) -> tuple[int, int]:
    """(H, W) of the map: ``params.size`` (same aspect as the working size within 2 %), or working / downscale."""
    h, w = work_size
    if params.size is None:
        return max(8, round(h / params.downscale)), max(8, round(w / params.downscale))
    mh, mw = params.size
    if abs(mh / mw - h / w) > 0.02 * h / w:
        raise InputError(f"--size {mw}x{mh} does not keep the run's aspect ratio ({w}x{h} working size)")
    if mh > h or mw > w:
        raise InputError(f"--size {mw}x{mh} is larger than the run's working size {w}x{h}")
    return mh, mw


def scaled_intrinsics(k_work, work_size, size) -> tuple[float, float, float, float]:
    sy, sx = size[0] / work_size[0], size[1] / work_size[1]
    fx, fy, cx, cy = (float(v) for v in k_work)
    return fx * sx, fy * sy, (cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5


def _grid_to(size, grid: np.ndarray, interp) -> np.ndarray:
    return cv2.resize(grid, (size[1], size[0]), interpolation=interp)


def _open_input(run_dir: Path, info: dict, input_path: Path | None, metric: bool):
    from droidw_cli.io.input import open_source

    path = Path(input_path) if input_path is not None else Path(str(info.get("input", "")))
    candidates = [path] if path.is_absolute() or input_path is not None else [path, run_dir.parent / path]
    found = next((p for p in candidates if p.exists()), None)
    if found is None:
        raise InputError(f"{run_dir}: the run's input {path} is not there any more; pass --input PATH")
    io = info.get("config", {}).get("io", {})
    source = open_source(found, stride=int(io.get("stride", 1)), start=int(io.get("start", 0)),
                         max_frames=int(io.get("max_frames", 0)), fps=float(io.get("fps", 30.0)),
                         strict_calibration=False)
    if hasattr(source, "load_depth"):
        source.load_depth = bool(metric and getattr(source, "has_depth", False))
    return source, found, int(io.get("target_area", 384 * 512))


def _gt_masks(folder: Path) -> dict[float, Path]:
    """timestamp → mask PNG from ``mask.txt`` (empty when the input has none)."""
    listing = folder / "mask.txt"
    if not listing.is_file():
        return {}
    out = {}
    for line in listing.read_text().splitlines():
        parts = line.split()
        if len(parts) >= 2 and not line.startswith("#"):
            out[round(float(parts[0]), 6)] = folder / parts[1]
    return out


def load_inputs(run_dir: Path, params: MapParams, input_path: Path | None = None) -> MapInputs:
    """Read the run and its input (see the module docstring); :class:`InputError` for anything unusable."""
    from droidw_cli.export.run_files import load_run
    from droidw_cli.io.calibration import load_calibration
    from droidw_cli.io.prepare import FramePreparer
    from droidw_cli.io.trajectory import read_tum

    if not run_dir.exists():
        raise InputError(f"{run_dir}: no such run folder; run `droidw track ... --out {run_dir}` first")
    npz = load_run(run_dir)
    check_multiview(npz, run_dir)
    info = _read_json(run_dir / "run.json")
    metric = bool(info.get("metric", False))
    traj = read_tum(run_dir / "traj.txt")
    source, folder, target_area = _open_input(run_dir, info, input_path, metric)
    calib = load_calibration(run_dir / "calib.txt", source.size)
    prep = FramePreparer(source.size, calib, target_area)
    work = tuple(int(v) for v in npz["work_size"])
    if tuple(prep.size) != work:
        raise InputError(f"{folder}: its frames prepare to {prep.size[1]}x{prep.size[0]}, the run's working size is "
                         f"{work[1]}x{work[0]}: not the input this run was tracked from")
    size = map_size(work, params)
    kf_index = np.asarray(npz["index"], dtype=np.int64)
    kf_set = set(kf_index.tolist())
    rest = [i for i in range(len(traj)) if i not in kf_set]
    held = rest[params.holdout_every // 2:: params.holdout_every]
    images, depths = _read_frames(source, prep, size, set(kf_set) | set(held), metric)
    missing = [i for i in [*kf_index.tolist(), *held] if i not in images]
    if missing:
        raise InputError(f"{folder}: frames {missing[:5]} of the run cannot be read from the input")
    has_masks = "dynamic" in npz and params.use_masks
    kf = _keyframe_views(npz, kf_index, images, depths, size, params, has_masks)
    gt = _gt_masks(folder)
    held_ts = traj.timestamps[held]
    mask_source = "input" if gt and all(round(float(t), 6) in gt for t in held_ts) else (
        "nearest keyframe" if "dynamic" in npz else "none")
    dyn = np.zeros((len(held), *size), dtype=bool)
    for j, (i, t) in enumerate(zip(held, held_ts)):
        if mask_source == "input":
            m = cv2.imread(str(gt[round(float(t), 6)]), cv2.IMREAD_GRAYSCALE)
            if m is None:
                raise InputError(f"{gt[round(float(t), 6)]}: cannot read the mask")
            work_m = prep.image(np.repeat(m[..., None], 3, axis=2))[..., 0].astype(np.float32) / 255.0
            dyn[j] = _grid_to(size, work_m, cv2.INTER_AREA) > 0.02
        elif mask_source == "nearest keyframe":
            k = int(np.argmin(np.abs(npz["timestamps"] - t)))
            dyn[j] = _grid_to(size, _dilate(npz["dynamic"][k], params.mask_dilate).astype(np.uint8),
                              cv2.INTER_NEAREST) > 0
    heldout = Views(np.array(held, dtype=np.int64), held_ts, traj.poses[held],
                    np.stack([images[i] for i in held]) if held else np.zeros((0, *size, 3), np.float32), dynamic=dyn)
    return MapInputs(kf, heldout, size, scaled_intrinsics(npz["intrinsics"], work, size), metric, has_masks,
                     mask_source, str(folder))


def _dilate(mask: np.ndarray, cells: int) -> np.ndarray:
    if cells <= 0:
        return mask.astype(bool)
    return cv2.dilate(mask.astype(np.uint8), np.ones((2 * cells + 1, 2 * cells + 1), np.uint8)) > 0


def _read_frames(source, prep, size, wanted: set[int], metric: bool):
    """index → image (H, W, 3) float32 and index → sensor depth (H, W) (RGB-D runs) for the wanted frames."""
    images, depths = {}, {}
    for frame in source:
        if frame.index not in wanted:
            continue
        img = prep.image(frame.image)
        images[frame.index] = _grid_to(size, img, cv2.INTER_AREA).astype(np.float32) / 255.0
        depth = frame.depth() if callable(frame.depth) else frame.depth
        if metric and depth is not None:
            depths[frame.index] = _grid_to(size, prep.depth(depth), cv2.INTER_NEAREST_EXACT)
    return images, depths


def _keyframe_views(npz, kf_index, images, depths, size, params: MapParams, has_masks: bool) -> Views:
    k = len(kf_index)
    disps = np.asarray(npz["disps"], dtype=np.float32)
    depth = np.zeros((k, *size), dtype=np.float32)
    static = np.ones((k, *size), dtype=bool)
    oids = np.full((k, *size), -1, dtype=np.int32)
    floor = 1e-2 * float(np.median(disps[disps > 0])) if (disps > 0).any() else 1e-6
    for j, i in enumerate(kf_index.tolist()):
        disp = _grid_to(size, disps[j], cv2.INTER_LINEAR)
        depth[j] = np.where(disp > floor, 1.0 / np.maximum(disp, floor), 0.0)
        sensor = depths.get(i)
        if sensor is not None:
            depth[j] = np.where(sensor > 0, sensor, depth[j])
        if has_masks:
            grow = _dilate(npz["dynamic"][j], params.mask_dilate).astype(np.uint8)
            static[j] = _grid_to(size, grow, cv2.INTER_NEAREST) == 0
            oids[j] = _grid_to(size, npz["object_ids"][j].astype(np.float32), cv2.INTER_NEAREST).astype(np.int32)
    return Views(kf_index, np.asarray(npz["timestamps"]), np.asarray(npz["poses_c2w"]),
                 np.stack([images[i] for i in kf_index.tolist()]), depth, static, oids)
