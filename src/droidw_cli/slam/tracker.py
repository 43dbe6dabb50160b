"""``droidw track``'s pipeline: frames in, a pose for every frame out.

One pass: motion filter → keyframes → frontend (initialisation, window BA
with uncertainty); every other frame goes to the trajectory filler with the
motion filter's flow from the newest keyframe, and gets its pose relative to
that keyframe once the keyframe has settled.  Then the global BA, and the
filler composes every frame's pose with its keyframe's final pose.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field

import cv2
import numpy as np
import torch
from tqdm import tqdm

from droidw_cli.ba.interface import BABackend
from droidw_cli.config import MotionFilterConfig, TrackConfig
from droidw_cli.dynamics.inloop import observed_disparity
from droidw_cli.dynamics.objects import DynamicRecord, finish
from droidw_cli.errors import InputError
from droidw_cli.geometry.camera import BA_SCALE, scale_intrinsics, unscale_intrinsics
from droidw_cli.geometry.poses import invert, to_matrix
from droidw_cli.io.calibration import Calibration
from droidw_cli.io.frames import Frame, FrameSource
from droidw_cli.io.jpeg import JpegStack
from droidw_cli.io.prepare import FramePreparer
from droidw_cli.runtime.heap import limit_arenas
from droidw_cli.runtime.prefetch import prefetched
from droidw_cli.runtime.threads import torch_threads, torch_threads_set
from droidw_cli.runtime.timing import StageTimer, Timed
from droidw_cli.slam.backend import GlobalBackend
from droidw_cli.slam.depth_prior import grid_disparity
from droidw_cli.slam.filler import TrajectoryFiller
from droidw_cli.slam.frontend import Frontend
from droidw_cli.slam.motion_filter import MotionFilter
from droidw_cli.slam.scout import Scout


@dataclass
class TrackResult:
    """Everything a run produces (poses camera-to-world, keyframe state at 1/8 resolution)."""

    timestamps: np.ndarray  # (N,) every input frame
    poses_c2w: np.ndarray  # (N, 4, 4)
    calibration: Calibration  # at the source resolution
    intrinsics_work: np.ndarray  # (4,) at the working resolution
    work_size: tuple[int, int]
    kf_index: np.ndarray  # (K,) frame positions of keyframes
    kf_timestamps: np.ndarray
    kf_poses_c2w: np.ndarray  # (K, 4, 4)
    kf_disps: np.ndarray  # (K, h, w) float32
    kf_images: JpegStack  # (K, H/s, W/s, 3) uint8 thumbnails, JPEG-encoded until read (np.asarray decodes all)
    kf_uncertainty: np.ndarray | None  # (K, h, w) float32
    kf_features: np.ndarray | None  # (K, C, h, w) float16
    kf_confidence: np.ndarray  # (K, h, w) float16 mean edge confidence of each pixel (stored as float16 too)
    kf_dynamic: np.ndarray | None  # (K, h, w) bool: every pixel ever masked dynamic (None: dynamics.mode none)
    kf_object_ids: np.ndarray | None  # (K, h, w) int16 object id, −1 none (int32 past 32767 ids)
    objects: np.ndarray | None  # (M, 8) keyframe, id, centre x, y (input px), world centroid x, y, z, area
    theta: np.ndarray | None
    initialised: bool
    calibration_estimated: bool = False  # --calib auto
    focal_estimated: bool = False  # … and the camera rotated enough to estimate f (else f is the initial guess)
    metric: bool = False  # the scale comes from sensor depth (RGB-D)
    timings: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    wall_time: float = 0.0
    kf_masked: np.ndarray | None = None  # (K, h, w) bool: kf_dynamic ∪ every pixel BA zeroed (static map exclusion)

    @property
    def fps(self) -> float:
        return len(self.timestamps) / self.wall_time if self.wall_time > 0 else float("nan")


class _Pending:
    """Features being computed on a worker; ``result()`` waits for them inside the ``features`` stage."""

    def __init__(self, future: Future, timer: StageTimer):
        self.future, self.timer = future, timer

    def result(self) -> torch.Tensor:
        with self.timer("features"):
            return self.future.result()


def _source_calibration(k_work: np.ndarray, preparer: FramePreparer) -> Calibration:
    """Invert the preparer's resize + crop to express working intrinsics at the source resolution."""
    (sh, sw), (rh, rw) = preparer.src_size, preparer.resized_size
    sx, sy = rw / sw, rh / sh
    oy, ox = preparer.offset
    fx, fy, cx, cy = (float(v) for v in k_work)
    return Calibration(fx / sx, fy / sy, (cx + ox + 0.5) / sx - 0.5, (cy + oy + 0.5) / sy - 0.5)


def _dynamic_record(fe: Frontend, preparer: FramePreparer) -> DynamicRecord | None:
    """Final dynamic masks and objects of the run, object centres in input-image pixels (None: masks off)."""
    if fe.cfg.dynamics.mode == "none":
        return None
    buf = fe.buffer
    n = len(buf)
    disps = observed_disparity(buf.disps[:n], buf.depth_prior[:n] if buf.has_prior else None)
    rec = finish(fe.masks, buf.poses[:n], disps, fe.shared.intrinsics, fe.cfg.dynamics, sensor_depth=buf.has_prior)
    (sh, sw), (rh, rw) = preparer.src_size, preparer.resized_size
    oy, ox = preparer.offset
    table = rec.table.copy()
    for col, off, scale in ((2, ox, rw / sw), (3, oy, rh / sh)):  # grid px → working px → input px
        work = (table[:, col] + 0.5) * BA_SCALE - 0.5
        table[:, col] = (work + off + 0.5) / scale - 0.5
    return DynamicRecord(rec.masks, rec.ids, table, rec.masked)


def motion_filter_config(cfg: TrackConfig, auto: bool) -> MotionFilterConfig:
    """The motion filter's settings for a run: with ``--calib auto`` (``auto``) a keyframe at least every
    ``max_gap_auto`` frames, for the views the focal length is estimated from (config.py)."""
    mf = cfg.motion_filter
    return dataclasses.replace(mf, max_gap=min(mf.max_gap, mf.max_gap_auto)) if auto else mf


def _prepared(source: FrameSource, preparer: FramePreparer) -> Iterator[tuple[Frame, np.ndarray, object]]:
    """(frame, working-size image, depth) per input frame.  The frame carries the working image, not the
    decoded one: the prefetch queue holds ``io.prefetch`` items, which at 4K input would otherwise be
    25 MB each.  The depth is a LazyDepth (decoded for keyframes only) or prepared."""
    for f in source:
        image = preparer.image(f.image)
        depth = f.depth if callable(f.depth) else (None if f.depth is None else preparer.depth(f.depth))
        yield Frame(f.index, f.timestamp, image), image, depth


def _confidence_half(fe: Frontend, chunk: int = 256) -> np.ndarray:
    """:meth:`Frontend.confidence` of every keyframe as float16, computed ``chunk`` keyframes at a time.

    keyframes.npz stores it as float16 anyway, and the archived keyframes keep
    it as float16; a float32 copy of all of them is 12 KB a keyframe.
    """
    n = len(fe.buffer)
    out = np.empty((n, *fe.buffer.grid), np.float16)
    for lo in range(0, n, chunk):
        out[lo:lo + chunk] = fe.confidence(lo, min(n, lo + chunk)).to(torch.float16).cpu().numpy()
    return out


class Tracker:
    """Runs the pipeline over one frame source."""

    def __init__(self, cfg: TrackConfig, backend: BABackend, correspondence, features=None, progress: bool = True):
        self.cfg = cfg
        self.backend = backend
        self.correspondence = correspondence
        self.features = features if cfg.uncertainty.enable else None
        self.progress = progress
        self.timer = StageTimer()

    def _first_pass(self, items, fe: Frontend, scout: Scout, filler: TrajectoryFiller, gba: GlobalBackend,
                    frames: list[tuple[int, float]], bar, grid: tuple[int, int], hw: tuple[int, int],
                    pool: ThreadPoolExecutor, preparer: FramePreparer) -> None:
        """Keyframes (the candidates the scout flagged) into the frontend; every other frame goes to the filler."""
        cfg, timer, s = self.cfg, self.timer, self.cfg.io.thumbnail_scale
        since = 0.0  # the motion filter's flow from the newest keyframe, summed over the candidates since
        while True:
            with timer("decode"):  # the wait for the prefetch thread
                item = next(items, None)
            if item is None:
                return
            frame, image, depth, is_kf = item  # the motion filter ran on the prefetch thread (slam/scout.py)
            frames.append((frame.index, frame.timestamp))
            if is_kf:  # a candidate that keyframe removal would drop at once stays an ordinary frame
                since += scout.flow(frame.index)
                is_kf = not fe.doomed(frame.index, since)
                if is_kf:
                    since = 0.0
            if is_kf:
                # the features run on a worker while the frontend matches the new edges; the
                # "features" stage is the time the BA then waits for them
                feats = None
                if self.features is not None:  # started by the scout during the last BA, or now
                    feats = _Pending(scout.features(frame.index) or pool.submit(self._extract, image), timer)
                prior = None
                if cfg.io.use_depth and callable(depth):  # a LazyDepth: decoded for keyframes only
                    with timer("decode"):
                        depth = depth()
                        depth = None if depth is None else preparer.depth(depth)
                if cfg.io.use_depth and depth is not None:
                    prior = grid_disparity(depth, grid)
                thumb = cv2.resize(image, (hw[1] // s, hw[0] // s), interpolation=cv2.INTER_AREA)
                k = fe.add_keyframe(frame.index, frame.timestamp, image, thumb, feats, prior)
                scout.taken(fe.initialised)
                with timer("global_ba"):
                    gba.keyframe_added(k, image)
                with timer("filler"):
                    filler.update()
            else:
                with timer("filler"):
                    filler.add_frame(frame.index, frame.timestamp, fe.buffer.frame_index[-1], image)
            bar.update(1)
            bar.set_postfix(kf=len(fe.buffer), refresh=False)

    def _extract(self, image: np.ndarray) -> torch.Tensor:
        x = torch.from_numpy(image).permute(2, 0, 1)[None].float() / 255.0
        return self.features.extract(x)[0]

    def run(self, source: FrameSource, calibration: Calibration | None) -> TrackResult:
        """Track ``source``; ``calibration`` None estimates the focal length (``--calib auto``)."""
        limit_arenas()  # before the run's threads take arenas of their own (runtime/heap.py)
        with torch_threads_set(torch_threads(self.cfg.threads)):
            return self._run(source, calibration)

    def _run(self, source: FrameSource, calibration: Calibration | None) -> TrackResult:
        cfg, timer = self.cfg, self.timer
        t_start = time.perf_counter()
        collected: list[str] = []
        h_src, w_src = source.size
        auto = calibration is None
        if auto:
            f = cfg.calib.focal_init * max(h_src, w_src)
            calibration = Calibration(f, f, (w_src - 1) / 2.0, (h_src - 1) / 2.0)
        preparer = FramePreparer(source.size, calibration.as_array(), cfg.io.target_area,
                                 calibration.distortion if calibration.has_distortion else None)
        hw = preparer.size
        grid = (hw[0] // BA_SCALE, hw[1] // BA_SCALE)
        k8 = torch.tensor(scale_intrinsics(np.asarray(preparer.intrinsics, dtype=np.float64), BA_SCALE), dtype=torch.float32)
        params = dataclasses.replace(cfg.ba, optimize_focal="shared") if auto else cfg.ba
        backend = Timed(self.backend, timer, "ba", ("ba_step", "uncertainty_step", "reproject"))
        corr = Timed(self.correspondence, timer, "flow", ("match", "match_pair", "match_all"))
        channels = self.features.channels if self.features is not None else 0
        fe = Frontend(cfg, params, backend, corr, grid, k8, channels)
        # the motion filter and each new keyframe's edge pair to the previous one run ahead on the
        # prefetch thread, beside the main thread's BA (without a prefetch thread, on the main one)
        ahead = cfg.frontend.match_ahead and cfg.io.prefetch > 0
        scout = Scout(MotionFilter(motion_filter_config(cfg, auto), cfg.correspondence.coarsest_scale,
                                   cfg.frontend.rotation_start > 0),
                      timer,
                      (lambda a, b, start: fe.match_adjacent(a, b, start, self.correspondence)) if ahead else None,
                      self._extract if ahead and self.features is not None else None)
        fe.starts = scout
        if ahead:
            fe.early = scout
        filler = TrajectoryFiller(fe, cfg.filler)
        fe.on_remove = filler.keyframe_removed
        gba = GlobalBackend(fe, cfg.backend, torch_threads(cfg.threads, alone=True))
        frames: list[tuple[int, float]] = []

        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            bar = tqdm(total=len(source), desc="track", unit="frame", disable=not self.progress, dynamic_ncols=True)
            restore = getattr(source, "load_depth", None)
            if restore is not None:
                source.load_depth = cfg.io.use_depth
                lazy = getattr(source, "lazy_depth", False)
                source.lazy_depth = True  # decode and prepare the depth of keyframes only (_first_pass)
            items = prefetched(scout.frames(_prepared(source, preparer)), cfg.io.prefetch)
            pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="droidw-features")
            failed = True
            try:
                self._first_pass(items, fe, scout, filler, gba, frames, bar, grid, hw, pool, preparer)
                failed = False
            except BaseException:
                filler.close()  # stops the filler's flow worker
                raise
            finally:
                # after a failure the queued feature jobs are dropped; after a run they are still read
                # (the keyframes' uncertainty), so they must finish: cancelling them raised CancelledError
                # whenever the worker lagged behind the last keyframes
                pool.shutdown(wait=True, cancel_futures=failed)
                scout.close()  # the prefetch thread may wait for the tracker to take a candidate
                items.close()  # stops the prefetch thread, also after an error
                if restore is not None:
                    source.load_depth = restore
                    source.lazy_depth = lazy
            bar.close()

            if not frames:
                raise InputError(f"{source.path}: no decodable frames")
            if not fe.initialised:
                collected.append(
                    f"too little parallax to build a map ({len(fe.buffer)} keyframe(s); initialisation needs "
                    f"{cfg.frontend.warmup_min} with {cfg.frontend.init_parallax:g} grid px of parallax, or "
                    f"{cfg.frontend.warmup}): the camera barely moved, so the trajectory stays at the identity"
                )
            if auto and not fe.focal_estimated:
                collected.append(
                    f"--calib auto: the camera never rotated {cfg.calib.min_rotation:g}° within a window, so the "
                    f"focal length was not estimated; it stays at the initial guess of {cfg.calib.focal_init:g} × "
                    f"the image's larger side (pass a calibration file for accurate results)")
            with torch_threads_set(gba.threads):  # the workers are done: every usable core (runtime/threads.py)
                with timer("global_ba"):
                    gba.finish()
                self.backend.release()  # the last BA has run: its cached window features are dead weight
                with timer("dynamics"):
                    dyn = _dynamic_record(fe, preparer)
                unc = fe.uncertainty()
                with timer("filler"):
                    poses_w2c = filler.finish()
            collected += [str(w.message) for w in caught if not issubclass(w.category, DeprecationWarning)]

        ident = torch.tensor([0, 0, 0, 0, 0, 0, 1.0])
        w2c = torch.stack([poses_w2c.get(idx, ident).cpu() for idx, _ in frames])
        buf = fe.buffer
        n_kf = len(buf)
        k_work = unscale_intrinsics(fe.shared.intrinsics.cpu().numpy().astype(np.float64), BA_SCALE)
        feats_np = theta = None
        if unc is not None:
            if not buf.frozen_u:  # a run longer than the backend's horizon archived the oldest features
                feats_np = buf.feature_block(0, n_kf).to(torch.float16).cpu().numpy()
            theta = fe.shared.theta.cpu().numpy().copy()
        wall = time.perf_counter() - t_start
        return TrackResult(
            timestamps=np.array([t for _, t in frames], dtype=np.float64),
            poses_c2w=to_matrix(invert(w2c)),
            calibration=_source_calibration(k_work, preparer),
            intrinsics_work=k_work,
            work_size=hw,
            kf_index=np.array(buf.frame_index, dtype=np.int64),
            kf_timestamps=np.array(buf.timestamps, dtype=np.float64),
            kf_poses_c2w=to_matrix(invert(buf.poses[:n_kf].cpu())) if n_kf else np.zeros((0, 4, 4)),
            kf_disps=buf.disps[:n_kf].cpu().numpy(),  # on the host a view: the buffer is not used any more
            kf_images=buf.thumbnail_stack(),
            kf_uncertainty=None if unc is None else unc.cpu().numpy(),
            kf_features=feats_np,
            kf_confidence=_confidence_half(fe),
            kf_dynamic=None if dyn is None else dyn.masks,
            kf_object_ids=None if dyn is None else dyn.ids,
            kf_masked=None if dyn is None else dyn.masked,
            objects=None if dyn is None else dyn.table,
            theta=theta,
            initialised=fe.initialised,
            calibration_estimated=auto,
            focal_estimated=fe.focal_estimated,
            metric=bool(buf.has_prior),
            timings=timer.as_dict(),
            warnings=list(dict.fromkeys(collected)),
            wall_time=wall,
        )
