"""Write a synthetic sequence as a TUM RGB-D style folder, or as a KITTI odometry sequence.

TUM layout (the default)::

    OUT/
      rgb/{t:.6f}.png      colour, 8-bit
      depth/{t:.6f}.png    16-bit, depth × depth_scale (5000 as in TUM), 0 = invalid / beyond max_depth
      mask/{t:.6f}.png     8-bit, 255 = ground-truth dynamic pixel (a walker is the nearest surface)
      rgb.txt depth.txt mask.txt   "# comments" then "timestamp path" lines
      groundtruth.txt      TUM trajectory, camera-to-world
      calib.txt            "fx fy cx cy"
      synth.json           the SynthConfig used and the generator version
      video.mp4            optional (mp4v; falls back to video.avi with MJPG)

KITTI layout (``layout="kitti"``, read back by :class:`~droidw_cli.io.datasets.KittiSource`)::

    OUT/
      image_0/NNNNNN.png   grey, single-channel 8-bit, when cfg.grey (KITTI's left grey camera)
      image_2/NNNNNN.png   else colour, 8-bit (KITTI's left colour camera)
      depth/NNNNNN.png     as in the TUM layout (×depth_scale), not a KITTI file
      mask/NNNNNN.png      as in the TUM layout, not a KITTI file
      times.txt            one timestamp in seconds a line, "%.12e" (exact to the microsecond)
      calib.txt            P0: … P3: and Tr: lines, 12 numbers each ("%.12e"), see :func:`kitti_calib_text`
      poses.txt            KITTI poses: the row-major top 3×4 of camera-to-world, relative to the first
                           frame as in KITTI (the first line is the identity)
      synth.json           as in the TUM layout, with "layout": "kitti"
      video.mp4            optional, as in the TUM layout

Only the left camera is rendered: the right cameras' matrices P1 and P3 are
written for tools that expect four lines, with KITTI's 0.54 m baseline.

The folder is written under a temporary name next to OUT and renamed at the
end, so OUT is either complete or absent.  PNGs are encoded on a thread pool
(cv2 releases the GIL) while the next frame renders; at most a few frames are
in flight, so memory stays bounded for any length.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import tempfile
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from droidw_cli.errors import UserError
from droidw_cli.io.trajectory import Trajectory, atomic_write_text, write_trajectory
from droidw_cli.synth.config import GENERATOR_VERSION, SynthConfig, SynthFrame
from droidw_cli.synth.render import build_scene, render_sequence

PNG_FAST = [cv2.IMWRITE_PNG_COMPRESSION, 1]
MAX_IN_FLIGHT = 6
LAYOUTS = ("tum", "kitti")
#: metres between KITTI's left and right cameras, for the P1 / P3 lines of calib.txt
KITTI_BASELINE = 0.54


def encode_depth(depth: np.ndarray, cfg: SynthConfig) -> np.ndarray:
    """Metres → uint16 (depth × depth_scale, rounded); 0 where invalid (≤ 0, non-finite or > max_depth)."""
    ok = np.isfinite(depth) & (depth > 0) & (depth <= cfg.max_depth)
    return np.where(ok, np.rint(np.where(ok, depth, 0) * cfg.depth_scale), 0).astype(np.uint16)


def _write_png(path: Path, img: np.ndarray) -> None:
    if not cv2.imwrite(str(path), img, PNG_FAST):
        raise OSError(f"could not write {path}")


def _list_text(kind: str, stamps: list[float]) -> str:
    head = f"# {kind} images of a droidw synthetic sequence\n# file: 'synth'\n# timestamp filename\n"
    return head + "".join(f"{t:.6f} {kind}/{t:.6f}.png\n" for t in stamps)


class _Video:
    """cv2.VideoWriter with mp4v, falling back to MJPG in an .avi."""

    def __init__(self, folder: Path, fps: float, size: tuple[int, int]):
        self.writer = None
        for name, codec in (("video.mp4", "mp4v"), ("video.avi", "MJPG")):
            w = cv2.VideoWriter(str(folder / name), cv2.VideoWriter_fourcc(*codec), float(fps), size)
            if w.isOpened():
                self.writer, self.name = w, name
                return
            w.release()
            (folder / name).unlink(missing_ok=True)
        raise UserError("could not open a video writer (tried mp4v and MJPG)")

    def write(self, bgr: np.ndarray) -> None:
        self.writer.write(bgr)

    def close(self) -> None:
        self.writer.release()


def _prepare_target(out_dir: Path, overwrite: bool) -> None:
    if out_dir.exists():
        if not out_dir.is_dir():
            raise UserError(f"{out_dir} exists and is not a folder")
        if any(out_dir.iterdir()) and not overwrite:
            raise UserError(f"{out_dir} exists and is not empty (pass overwrite=True / --overwrite)")
    out_dir.parent.mkdir(parents=True, exist_ok=True)


def kitti_calib_text(cfg: SynthConfig) -> str:
    """A KITTI odometry ``calib.txt`` for ``cfg``'s camera.

    P0 = P2 = K [I | 0] (the rendered left camera; KITTI's grey and colour
    cameras sit 6 cm apart, the generator renders one), P1 = P3 = K [I | t]
    with t = (−b, 0, 0), i.e. a last column (−fx·b, 0, 0), b = 0.54 m (right
    cameras, not rendered), and ``Tr`` (KITTI's Velodyne-to-camera transform)
    the identity: there is no laser scanner.
    """
    left = np.hstack([cfg.K, np.zeros((3, 1))])
    right = left.copy()
    right[0, 3] = -cfg.K[0, 0] * KITTI_BASELINE
    rows = (("P0", left), ("P1", right), ("P2", left), ("P3", right), ("Tr", np.eye(4)[:3]))
    return "".join(f"{name}: " + " ".join(f"{v:.12e}" for v in m.ravel()) + "\n" for name, m in rows)


def write_sequence(cfg: SynthConfig, out_dir: str | Path, video: bool = False, progress: bool = True,
                   overwrite: bool = False, layout: str = "tum") -> Path:
    """Render ``cfg`` and write the folder ``out_dir`` in ``layout`` (``tum`` or ``kitti``); returns its path.

    ``video`` also writes ``video.mp4`` (or ``video.avi``).  ``progress``
    shows a tqdm bar on stderr.  An existing non-empty ``out_dir`` is an
    error unless ``overwrite``.
    """
    if layout not in LAYOUTS:
        raise UserError(f"unknown layout {layout!r} (use one of {', '.join(LAYOUTS)})")
    out_dir = Path(out_dir).expanduser().absolute()
    _prepare_target(out_dir, overwrite)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".tmp", dir=out_dir.parent))
    try:
        _write_into(cfg, tmp, video, progress, layout)
        if out_dir.exists():
            old = out_dir.with_name(f".{out_dir.name}.old-{os.getpid()}")
            os.replace(out_dir, old)
            os.replace(tmp, out_dir)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out_dir


def _image_folder(cfg: SynthConfig, layout: str) -> str:
    if layout == "tum":
        return "rgb"
    return "image_0" if cfg.grey else "image_2"


def _write_into(cfg: SynthConfig, folder: Path, video: bool, progress: bool, layout: str) -> None:
    images = _image_folder(cfg, layout)
    for sub in (images, "depth", "mask"):
        (folder / sub).mkdir()
    scene = build_scene(cfg)
    frames = render_sequence(cfg, scene=scene)
    if progress:
        from tqdm import tqdm

        frames = tqdm(frames, total=cfg.frames, desc="synth", unit="frame", leave=False)
    stamps: list[float] = []
    poses = np.zeros((cfg.frames, 4, 4))
    vid = _Video(folder, cfg.fps, (cfg.width, cfg.height)) if video else None
    pending: list[Future] = []
    # PNGs on two workers; the video on its own single worker, which keeps the frames in order
    with ThreadPoolExecutor(max_workers=2) as pool, ThreadPoolExecutor(max_workers=1) as vpool:
        try:
            for frame in frames:
                name = f"{frame.timestamp:.6f}.png" if layout == "tum" else f"{frame.index:06d}.png"
                bgr = _submit(pool, pending, folder, frame, cfg, images, name)
                if vid is not None:
                    pending.append(vpool.submit(vid.write, bgr))
                stamps.append(frame.timestamp)
                poses[frame.index] = frame.pose_c2w
                while len(pending) > MAX_IN_FLIGHT * 4:
                    pending.pop(0).result()
            for f in pending:
                f.result()
        finally:
            for f in pending:
                f.cancel()
            vpool.shutdown(wait=True)
            if vid is not None:
                vid.close()
            if progress:
                frames.close()
    if layout == "tum":
        _write_tum_files(folder, cfg, stamps, poses)
    else:
        _write_kitti_files(folder, cfg, stamps, poses)
    meta = {"generator": "droidw_cli.synth", "version": GENERATOR_VERSION, "config": dataclasses.asdict(cfg),
            "walkers": len(scene.walkers)}
    if layout != "tum":  # the TUM folder's synth.json stays as it always was
        meta["layout"] = layout
    atomic_write_text(folder / "synth.json", json.dumps(meta, indent=2) + "\n")


def _write_tum_files(folder: Path, cfg: SynthConfig, stamps: list[float], poses: np.ndarray) -> None:
    atomic_write_text(folder / "rgb.txt", _list_text("rgb", stamps))
    atomic_write_text(folder / "depth.txt", _list_text("depth", stamps))
    atomic_write_text(folder / "mask.txt", _list_text("mask", stamps))
    write_trajectory(folder / "groundtruth.txt", Trajectory(np.array(stamps), poses))
    fx, fy, cx, cy = cfg.intrinsics
    atomic_write_text(folder / "calib.txt", f"{fx:.6f} {fy:.6f} {cx:.6f} {cy:.6f}\n")


def _write_kitti_files(folder: Path, cfg: SynthConfig, stamps: list[float], poses: np.ndarray) -> None:
    atomic_write_text(folder / "times.txt", "".join(f"{t:.12e}\n" for t in stamps))
    atomic_write_text(folder / "calib.txt", kitti_calib_text(cfg))
    relative = np.linalg.inv(poses[0]) @ poses  # KITTI: poses in the first camera's frame
    relative[0] = np.eye(4)  # exactly, not up to rounding
    write_trajectory(folder / "poses.txt", Trajectory(np.array(stamps), relative), fmt="kitti")


def _submit(pool: ThreadPoolExecutor, pending: list[Future], folder: Path, frame: SynthFrame,
            cfg: SynthConfig, images: str, name: str) -> np.ndarray:
    """Queue the frame's image, depth and mask PNGs; returns the BGR image (for the video).

    ``images == "image_0"`` (KITTI grey): the single-channel image, which the
    grey config renders as luma in all three channels."""
    bgr = np.ascontiguousarray(frame.rgb[..., ::-1])
    image = np.ascontiguousarray(frame.rgb[..., 0]) if images == "image_0" else bgr
    pending.append(pool.submit(_write_png, folder / images / name, image))
    pending.append(pool.submit(_write_png, folder / "depth" / name, encode_depth(frame.depth, cfg)))
    pending.append(pool.submit(_write_png, folder / "mask" / name, frame.mask.astype(np.uint8) * np.uint8(255)))
    return bgr
