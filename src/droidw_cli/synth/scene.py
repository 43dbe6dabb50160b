"""The synthetic scene: room, furniture, walkers on their paths, camera path, texture atlas.

The camera path is the family ``cfg.motion`` (:mod:`droidw_cli.synth.motions`);
everything below only uses its ``position``, ``target`` and ``pose``.

Coverage of the image by walkers is estimated cheaply by casting rays at
48 × 36 (for 4:3 images) against the walkers' boxes only, on up to 90 frames
spread over the sequence.

The *far* walkers (1, 2, …) loop in the back part of the room (y ≥ FAR_Y).
Their loops are drawn up to 8 times until their combined coverage stays
below target − 0.08 (else the best draw is kept).  With ``cfg.apart``, once
walker 0 is tuned, a far walker that would come within 0.7 m of a walker
before it is drawn again (:mod:`droidw_cli.synth.crowd`); without it, walkers
may walk through each other.

Walker 0 is the *close* walker: its ellipse is laid out so that at the middle
of the sequence it crosses the view sideways at distance d from the camera.
d is tuned by bisection so that the largest coverage over the sequence is
close to ``cfg.target_coverage``: coverage falls as d grows, so bisection
converges; a d that brings the walker within 0.45 m of the camera at any
frame counts as "too close".  The paths therefore depend on ``cfg.frames``
(and fps, speeds); the room, textures and camera path do not.

Rendering: frame k is cast at its own time; with ``cfg.blur`` its colour is
the exposure average of sub-frames (:mod:`droidw_cli.synth.exposure`), then
the photometric chain (:mod:`droidw_cli.synth.photometric`) applies gain,
noise and JPEG.  Depth, mask and pose are always those of frame k itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from droidw_cli.geometry.camera import scale_intrinsics
from droidw_cli.synth import exposure, layout
from droidw_cli.synth.crowd import extent, far_walk, keep_apart, shrink, slide
from droidw_cli.synth.atlas import AtlasBuilder
from droidw_cli.synth.config import FOLLOW_MOTIONS, STREET_MOTIONS, SynthConfig, SynthFrame
from droidw_cli.synth.follow import follow_world
from droidw_cli.synth.motions import CameraMotion, camera_motion
from droidw_cli.synth.paths import EllipseWalk, make_walk
from droidw_cli.synth.photometric import Photometric, to_linear
from droidw_cli.synth.raycast import Box, RayCaster, box_hits, shade
from droidw_cli.synth.street_textures import sky as street_sky
from droidw_cli.synth.street_world import LineWalk, street_world

#: texels (azimuth × elevation from the horizon up) of a street's sky panel (synth.raycast)
SKY_PANEL = (2048, 384)
COVER_WIDTH = 48
COVER_FRAMES = 90
MIN_CLEARANCE = 0.45  # metres between the camera and a walker's axis
#: a walker drawn again to keep apart may raise the walkers' largest coverage of the image to
#: max(target, the first draws') + COVER_SLACK and their mean coverage to the first draws' × COVER_MEAN
COVER_SLACK = 0.03
COVER_MEAN = 1.1


@dataclass(frozen=True, eq=False)
class Walker:
    """Rigid parts (centre in body coordinates, half extents, atlas table, texel density) moving along ``walk``
    (a walker, or a car in a street)."""

    walk: EllipseWalk | LineWalk
    centres: tuple[np.ndarray, ...]
    halves: tuple[np.ndarray, ...]
    tables: tuple[np.ndarray, ...]
    rhos: tuple[float | None, ...] = ()

    def boxes(self, t: float) -> list[Box]:
        rot, pos = self.walk.state(t)
        parts = zip(self.centres, self.halves, self.tables, self.rhos or (None,) * len(self.centres))
        return [Box(pos + rot @ c, rot, h, tab, dynamic=True, rho=r) for c, h, tab, r in parts]


def _rho(cfg: SynthConfig, spec) -> float | None:
    """A box's own texel density for the caster (None: the scene's)."""
    return None if spec.rho_scale == 1.0 else cfg.rho * spec.rho_scale


class _CloseWalkFactory:
    """Walker 0's loop as a function of its distance d to the camera at the middle frame.

    The loop is an ellipse elongated across the view: its near point is d
    metres ahead of the camera (along the viewing direction projected on the
    floor) and the walker passes it, walking sideways, at the middle frame.
    It slides sideways (keeping d) to stay inside the room.
    """

    def __init__(self, rng: np.random.Generator, room: np.ndarray, camera: CameraMotion, t_cam: float, t_walk: float):
        self.room, self.t_walk = room, t_walk
        pos, tgt = camera.position(t_cam), camera.target(t_cam)
        fwd = (tgt - pos)[:2]
        self.fwd = fwd / np.linalg.norm(fwd)
        self.cam_xy = pos[:2]
        self.a, self.b = rng.uniform(1.1, 1.6), rng.uniform(0.35, 0.6)
        self.speed = rng.uniform(0.9, 1.2)
        self.direction = int(rng.choice([-1, 1]))

    def __call__(self, d: float) -> EllipseWalk:
        lo, hi = layout.walker_region(self.room, 0.3)
        e1 = np.array([self.fwd[1], -self.fwd[0]])  # e₂ = fwd: the loop extends away from the camera
        q = self.cam_xy + d * self.fwd  # where the walker should be at the middle frame
        a, b = self.a, self.b
        while a > 0.8:  # a shorter loop rather than one slid out of view ...
            ext = extent(e1, a, b)
            if np.all(q + b * self.fwd - ext >= lo) and np.all(q + b * self.fwd + ext <= hi):
                break
            a = max(0.8, 0.95 * a)
        a, b = shrink(e1, a, b, lo, hi)
        centre0 = q + b * self.fwd
        centre = slide(centre0, e1, extent(e1, a, b), lo, hi)  # ... but slide it if it must
        # pass the point of the loop's near side nearest to q at the middle frame
        c = float(np.clip(-(centre - centre0) @ e1 / a, -1.0, 1.0))
        s_at = float(np.arctan2(-np.sqrt(1.0 - c * c), c))
        return make_walk(centre, e1, a, b, self.speed, self.direction, s_at, self.t_walk)


def _tune_close_walk(cfg: SynthConfig, factory: _CloseWalkFactory, walker0_parts, other_hits: np.ndarray,
                     poses: np.ndarray, t_walk: np.ndarray, intr_small: np.ndarray, size,
                     clearance: tuple[np.ndarray, np.ndarray]) -> EllipseWalk:
    """Bisection on the close distance d ∈ [0.5, 3.5] m for max coverage ≈ target.

    Coverage is measured at the sampled ``poses``/``t_walk``; the clearance
    (camera xy, walker time) is checked on every frame.
    """
    w, h = size
    cam_xy, t_dense = clearance

    def max_cover(d: float) -> float:
        walk = factory(d)
        if np.min(np.linalg.norm(walk.state(t_dense)[1][:, :2] - cam_xy, axis=1)) < MIN_CLEARANCE:
            return 1.0
        rot, pos = walk.state(t_walk)
        hits = other_hits.copy()
        for c, half in walker0_parts:
            hits |= box_hits(pos + rot @ c, rot, half, poses, intr_small, w, h)
        return float(hits.mean(1).max())

    target = cfg.target_coverage
    lo, hi = 0.5, 3.5
    best = (abs(max_cover(hi) - target), hi)
    for _ in range(9):
        mid = 0.5 * (lo + hi)
        cov = max_cover(mid)
        best = min(best, (abs(cov - target), mid))
        if abs(cov - target) < 0.02:
            break
        if cov > target:
            lo = mid
        else:
            hi = mid
    return factory(best[1])


class Scene:
    """Everything needed to render any frame of a :class:`SynthConfig`, in any order."""

    def __init__(self, cfg: SynthConfig):
        self.cfg = cfg
        seed = cfg.seed
        self.photometric = Photometric.of(cfg)
        street = cfg.motion in STREET_MOTIONS
        if street:  # a camera travelling down a street (synth.street_world) or following a mover there (synth.follow)
            world = follow_world(cfg) if cfg.motion in FOLLOW_MOTIONS else street_world(cfg)
            self.room, self.street, self.camera = None, world.plan, world.camera
            statics, walker_parts, walks = world.statics, world.mover_parts, world.paths
        else:
            self.room, self.street = layout.room_size(seed), None
            self.camera = camera_motion(cfg.motion, seed, self.room)
            statics = [layout.room_spec(seed, self.room), *layout.furniture_specs(seed, self.room)]
            walker_parts = [layout.walker_specs(seed, i) for i in range(cfg.n_movers)]
            walks = self._walks(walker_parts)

        builder = AtlasBuilder(cfg.rho)
        for spec in statics:  # the first is the room (or the street's outer box), seen from inside
            builder.add_box(spec.half, spec.materials, spec.shades, spec.seed, group=0, rho_scale=spec.rho_scale)
        for spec in (p for parts in walker_parts for p in parts):
            builder.add_box(spec.half, spec.materials, spec.shades, spec.seed, group=1, rho_scale=spec.rho_scale)
        if street:
            builder.add_panel(SKY_PANEL[0], SKY_PANEL[1], street_sky, (seed, 11, 2), group=2)
        self.atlas, tables = builder.build()
        sky = tables[-1][0] if street else None
        self.static_boxes = [Box(s.centre, s.rotation, s.half, t, inside=i == 0, rho=_rho(cfg, s),
                                 sky=sky if i == 0 else None) for i, (s, t) in enumerate(zip(statics, tables))]
        rest = iter(tables[len(statics):])
        self.walkers = [Walker(walk, tuple(p.centre for p in parts), tuple(p.half for p in parts),
                               tuple(next(rest) for _ in parts), tuple(_rho(cfg, p) for p in parts))
                        for walk, parts in zip(walks, walker_parts)]
        self.caster = RayCaster(cfg.intrinsics, cfg.width, cfg.height, cfg.rho)

    # -- time and poses -----------------------------------------------------
    def camera_time(self, k) -> np.ndarray:
        return np.asarray(k, np.float64) / self.cfg.fps * self.cfg.camera_speed

    def walker_time(self, k) -> np.ndarray:
        return np.asarray(k, np.float64) / self.cfg.fps * self.cfg.mover_speed

    def pose(self, k) -> np.ndarray:
        """Camera-to-world pose(s) of frame(s) k, (…, 4, 4) float64."""
        return self.camera.pose(self.camera_time(k))

    def _walks(self, walker_parts) -> list[EllipseWalk]:
        """The walkers' paths: the far ones by rejection sampling (their combined coverage
        below target − 0.08 if possible, 8 tries), then walker 0 tuned to the target, then (``cfg.apart``)
        the far ones that meet a walker before them drawn again (:func:`~droidw_cli.synth.crowd.keep_apart`)."""
        cfg = self.cfg
        if not walker_parts:
            return []
        seed = cfg.seed
        ks = np.unique(np.round(np.linspace(0, cfg.frames - 1, min(cfg.frames, COVER_FRAMES))))
        poses, t_walk = self.pose(ks), self.walker_time(ks)
        cw = COVER_WIDTH
        ch = max(8, int(round(cw * cfg.height / cfg.width)))
        intr_small = scale_intrinsics(cfg.intrinsics, cfg.width / cw)

        def hits_of(walk: EllipseWalk, parts) -> np.ndarray:
            rot, pos = walk.state(t_walk)
            out = np.zeros((len(ks), cw * ch), bool)
            for p in parts:
                out |= box_hits(pos + rot @ p.centre, rot, p.half, poses, intr_small, cw, ch)
            return out

        best = None
        for attempt in range(8):
            far = [far_walk(np.random.default_rng([seed, layout.TAG_PATH + i, attempt]), self.room)
                   for i in range(1, len(walker_parts))]
            others = np.zeros((len(ks), cw * ch), bool)
            for walk, parts in zip(far, walker_parts[1:]):
                others |= hits_of(walk, parts)
            cover = float(others.mean(1).max())
            if best is None or cover < best[0]:
                best = (cover, far, others)
            if cover <= cfg.target_coverage - 0.08:
                break
        _, far, others = best
        mid = (cfg.frames - 1) / 2.0
        factory = _CloseWalkFactory(np.random.default_rng([seed, layout.TAG_PATH]), self.room, self.camera,
                                    float(self.camera_time(mid)), float(self.walker_time(mid)))
        parts0 = [(p.centre, p.half) for p in walker_parts[0]]
        dense = np.unique(np.round(np.linspace(0, cfg.frames - 1, min(cfg.frames, 20000))))
        clearance = (self.camera.position(self.camera_time(dense))[:, :2], self.walker_time(dense))
        walks = [_tune_close_walk(cfg, factory, parts0, others, poses, t_walk, intr_small, (cw, ch), clearance), *far]
        if not cfg.apart:
            return walks
        hits: dict[int, tuple[EllipseWalk, np.ndarray]] = {}  # id → (walk, its hits): each walk cast once

        def cover(walks: list[EllipseWalk]) -> tuple[float, float]:
            out = np.zeros((len(ks), cw * ch), bool)
            for walk, parts in zip(walks, walker_parts):
                if id(walk) not in hits:
                    hits[id(walk)] = (walk, hits_of(walk, parts))
                out |= hits[id(walk)][1]
            share = out.mean(1)
            return float(share.max()), float(share.mean())

        largest, mean = cover(walks)
        cap = (max(cfg.target_coverage, largest) + COVER_SLACK, mean * COVER_MEAN)

        def admits(walks: list[EllipseWalk]) -> bool:
            new_largest, new_mean = cover(walks)
            return new_largest <= cap[0] and new_mean <= cap[1]

        return keep_apart(walks, clearance[1], clearance[0], self.room, seed, admits)

    # -- rendering ------------------------------------------------------------
    def boxes(self, k: float, static: bool = True, movers: bool = True) -> list[Box]:
        """The boxes at (possibly fractional) frame time k."""
        out = list(self.static_boxes) if static else []
        if movers:
            t = float(self.walker_time(k))
            for w in self.walkers:
                out += w.boxes(t)
        return out

    def render(self, k: int, static: bool = True, movers: bool = True,
               pose_c2w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rgb uint8, depth float32 metres with 0 where nothing is hit, mask bool) of frame k.

        ``static``/``movers`` leave out the room or the walkers (for checks);
        ``pose_c2w`` renders frame k's scene from another viewpoint (then
        held still through the exposure: only the walkers blur).  The colour
        gets the config's blur, gain, noise and JPEG; depth and mask are exact.
        """
        pose = self.pose(k) if pose_c2w is None else np.asarray(pose_c2w, np.float64)
        hits = self.caster.cast(self.boxes(k, static, movers), pose)
        rgb = shade(self.atlas, hits)
        depth = hits.depth
        depth[~np.isfinite(depth)] = 0.0
        linear = self._exposure(k, static, movers, pose_c2w, rgb, depth) if self.cfg.blur > 0 else None
        out = self.photometric.finish(k, rgb, linear)
        if self.cfg.grey:
            out = cv2.cvtColor(cv2.cvtColor(out, cv2.COLOR_RGB2GRAY), cv2.COLOR_GRAY2RGB)
        return out, depth, hits.dynamic

    def exposure_samples(self, k: int, depth: np.ndarray | None = None, static: bool = True, movers: bool = True,
                         pose_c2w: np.ndarray | None = None) -> np.ndarray:
        """The sub-frame times (fractional frame indices) averaged for frame k's motion blur.

        ``depth`` is frame k's depth (rendered when not given); see :mod:`droidw_cli.synth.exposure`.
        """
        cfg = self.cfg
        if cfg.blur <= 0:
            return np.array([float(k)])
        if depth is None and static:
            depth = self.caster.cast(self.boxes(k, static, movers), self._pose_at(k, pose_c2w)).depth
            depth[~np.isfinite(depth)] = 0.0
        start, end = k - 0.5 * cfg.blur, k + 0.5 * cfg.blur
        poses = (self._pose_at(start, pose_c2w), self._pose_at(end, pose_c2w))
        corners = (exposure.box_corners(self.boxes(start, static=False, movers=movers)),
                   exposure.box_corners(self.boxes(end, static=False, movers=movers)))
        smear = exposure.image_motion(cfg.K, (cfg.width, cfg.height), self._pose_at(k, pose_c2w), poses,
                                      depth if static else None, corners)
        return k + exposure.sample_offsets(cfg.blur, exposure.sample_count(smear, cfg.blur_samples))

    def _pose_at(self, s: float, pose_c2w: np.ndarray | None) -> np.ndarray:
        return self.pose(s) if pose_c2w is None else np.asarray(pose_c2w, np.float64)

    def _exposure(self, k: int, static: bool, movers: bool, pose_c2w: np.ndarray | None, rgb: np.ndarray,
                  depth: np.ndarray) -> np.ndarray:
        """Mean linear intensity of the exposure's sub-frames (frame k's own render ``rgb`` reused)."""
        times = self.exposure_samples(k, depth, static, movers, pose_c2w)
        total = np.zeros(rgb.shape, np.float32)
        for s in times:
            if s == k:
                sub = rgb
            else:
                sub = shade(self.atlas, self.caster.cast(self.boxes(s, static, movers), self._pose_at(s, pose_c2w)))
            total += to_linear(sub)
        return total * np.float32(1.0 / len(times))

    def frame(self, k: int) -> SynthFrame:
        if not 0 <= k < self.cfg.frames:
            raise ValueError(f"frame index {k} out of range [0, {self.cfg.frames})")
        rgb, depth, mask = self.render(k)
        return SynthFrame(self.cfg.timestamp(k), rgb, depth, mask, self.pose(k), int(k))
