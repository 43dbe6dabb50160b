"""Correspondences from OpenCV's DIS optical flow (Kroeger et al., ECCV 2016).

``match`` runs DIS i → j and j → i on grayscale images, scores each pixel
(:mod:`droidw_cli.correspondence.confidence`) and brings flow and weight to
the 1/8 grid by block averaging (:mod:`droidw_cli.correspondence.grid`).
With ``init_flow`` the forward pass starts from it and the backward pass
from its approximate inverse; DIS uses a passed-in float32 (H, W, 2) flow as
its initialisation, which makes ~100 px motions recoverable.

DIS is deterministic, also across thread counts (its spatial propagation
uses a fixed number of stripes).

DIS picks its coarsest pyramid level from the image size alone (OpenCV's
``dis_flow.cpp``; patch size p):

    L = min(⌊log2(max(H, W) / 4p) + ½⌋, ⌊log2(min(H, W) / p)⌋)

so motions beyond a few patches at level L are lost, and L drops by one at a
size threshold: MEDIUM (p = 8) takes level 4 (1/16) at 384 × 512 and at
272 × 368, but level 3 at 272 × 360 (the ``fast`` config's working size for
640 × 480 input), where a 44 px shift that level 4 finds is lost
(``tests/test_correspondence_pyramid.py``).  With
``correspondence.coarsest_scale`` k > 0 a flow without a start (the edges',
the filler's, :meth:`DISCorrespondence.mean_flow`'s and the motion
filter's, :mod:`droidw_cli.slam.motion_filter`) runs the levels beyond L
first, on the images padded (edge pixels repeated, right and bottom) to the
smallest size at which DIS reaches k relative to the working size
(:func:`padded_size`, :func:`level_at`); that flow, cropped, starts the
usual call (:func:`calc_deep`).
"""

from __future__ import annotations

import math
import threading

import cv2
import numpy as np
import torch

from droidw_cli.config import CorrespondenceConfig
from droidw_cli.correspondence.base import Correspondence, CorrespondenceSource, MatchCall
from droidw_cli.correspondence.confidence import (flow_confidence, flow_map, inside_mask, invert_flow, remap,
                                                   sample_at_flow)
from droidw_cli.correspondence.grid import area_downsample, flow_to_target, mean_length, validate_flow, validate_image
from droidw_cli.errors import ConfigError

#: name → (OpenCV preset, overrides).  ``fine`` (the filler's flow) is FAST with its finest pyramid
#: level at 1/2 instead of 1/4 of the working size, a sparser patch grid and no variational
#: refinement.  With FAST's 5 refinement iterations it read 0.04 px median deviation from a long
#: MEDIUM run on a 384 × 512 walk frame pair, against FAST's 0.15; the refinement was 64 % of its
#: time (21.2 against 7.7 ms a walk pair, one thread), and the filler's area average onto the grid
#: smooths as much: ATE geometric mean 1.005× over 18 runs without it (docs/benchmarks.md, "The
#: filler's flow without variational refinement").
PRESETS = {
    "ultrafast": (cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, {}),
    "fast": (cv2.DISOPTICAL_FLOW_PRESET_FAST, {}),
    "fine": (cv2.DISOPTICAL_FLOW_PRESET_FAST,
             {"FinestScale": 1, "PatchStride": 6, "VariationalRefinementIterations": 0}),
    "medium": (cv2.DISOPTICAL_FLOW_PRESET_MEDIUM, {}),
}


def create_dis(name: str, smoothness: float = 0.0):
    """An OpenCV DIS optical flow object for a preset name of :data:`PRESETS`.

    ``smoothness`` > 0 replaces the weight α of the smoothness term of DIS's
    variational refinement (the preset's own is 20).  A smaller α smooths less
    across depth edges: with the rotation held at the truth, the walk's
    translation read from MEDIUM's flow goes from 0.9968 to 0.9987 of the
    truth at α = 2 (``benchmarks/flow_bench.py``, 8-frame pairs).
    """
    preset, overrides = PRESETS[name]
    dis = cv2.DISOpticalFlow_create(preset)
    for key, value in overrides.items():
        getattr(dis, "set" + key)(value)
    if smoothness > 0:
        dis.setVariationalRefinementAlpha(float(smoothness))
    return dis


def dis_objects(name: str, smoothness: float = 0.0, cache: dict | None = None):
    """:func:`calc_deep`'s ``objects(kind)`` for preset ``name``: one DIS object per kind, created on first use
    and kept in ``cache`` under (name, seeded, smoothness, finest scale or None).

    OpenCV's DIS keeps state between calls: a call without an initial flow that follows one
    with an initial flow starts from a leftover of it (up to 4 px difference on a walk pair
    with MEDIUM), so calls with and without one use separate objects.  Otherwise DIS keeps
    nothing between calls, so each result depends on its inputs only.
    """
    cache = {} if cache is None else cache

    def get(kind):
        finest = kind if isinstance(kind, int) else None
        key = (name, kind == "seeded", smoothness, finest)
        if key not in cache:
            cache[key] = create_dis(name, smoothness)
            if finest is not None:
                cache[key].setFinestScale(finest)
        return cache[key]
    return get


# mean_flow runs FAST DIS at 1/2 resolution: about 3 ms at 448×592 here.  ULTRAFAST at 1/4
# (0.6 ms) reads 1-3 px of spurious mean flow on a static-camera clip (vtest), too close
# to the motion filter's 3 px threshold; FAST at 1/2 reads 0.3-1.4 px there.
MEAN_FLOW_SCALE = 2
MEAN_FLOW_PRESET = "fast"
# quick_target (the filler's flow, correspondence.quick_preset): one direction at the working
# resolution.  At half resolution the filler's camera centres were 2-3× worse on the generator's
# walks; "fine" instead of "fast" took the 600-frame static control from 0.51 to 0.34 cm.


def dis_levels(height: int, width: int, patch: int) -> int:
    """The coarsest pyramid level (scale 1/2^L) OpenCV's DIS uses for a height × width image (module docstring)."""
    return min(int(math.log(max(height, width) / (4.0 * patch)) / math.log(2.0) + 0.5),
               int(math.log(min(height, width) / patch) / math.log(2.0)))


def padded_size(height: int, width: int, patch: int, level: int) -> tuple[int, int]:
    """The smallest (H, W) ≥ (height, width) at which :func:`dis_levels` is at least ``level``: both sides
    grown to p·2^level, then the longer one until ⌊log2(max / 4p) + ½⌋ reaches ``level``."""
    side = patch * 2 ** level
    h, w = max(height, side), max(width, side)
    long = max(h, w)
    while dis_levels(h, w, patch) < level:
        long += 1
        h, w = (long, w) if h >= w else (h, long)
    return h, w


def level_at(coarsest_scale: int, downscale: int) -> int:
    """The level, in an image ``downscale`` times smaller than the working size, that is 1/2^k of the
    working size (k = ``coarsest_scale``; 0 stays 0, DIS's own choice)."""
    return max(0, coarsest_scale - int(math.log2(downscale))) if coarsest_scale > 0 else 0


def calc_deep(objects, gray_i: np.ndarray, gray_j: np.ndarray, start: np.ndarray | None, level: int) -> np.ndarray:
    """DIS flow gray_i → gray_j from ``start`` (or none), reaching pyramid level ``level`` (1/2^level) at least.

    ``objects(kind)`` gives the DIS objects of one preset: ``"plain"`` (for calls without a start),
    ``"seeded"`` (with one) and an int F (finest scale F).  When no start is given and DIS's own
    coarsest level L for this size is below ``level``, the levels it would skip run first, on the
    images padded to :func:`padded_size` by repeating their edge pixels (finest scale L + 1, a
    coarse image, so cheap); their flow, cropped, is the start of the usual call, which then
    refines it from level L down.
    """
    h, w = gray_i.shape[:2]
    if start is not None:
        if warped_out(start):
            return calc_warped(objects, gray_i, gray_j, start, level)
        return objects("seeded").calc(gray_i, gray_j, start)
    plain = objects("plain")
    if level <= 0:  # DIS's own choice: the default, so nothing else on this path
        return plain.calc(gray_i, gray_j, None)
    patch = plain.getPatchSize()
    own = dis_levels(h, w, patch)
    if level <= own:
        return plain.calc(gray_i, gray_j, None)
    big_h, big_w = padded_size(h, w, patch, level)

    def pad(a: np.ndarray) -> np.ndarray:
        return cv2.copyMakeBorder(a, 0, big_h - h, 0, big_w - w, cv2.BORDER_REPLICATE)
    coarse = objects(own + 1).calc(pad(gray_i), pad(gray_j), None)
    return objects("seeded").calc(gray_i, gray_j, np.ascontiguousarray(coarse[:h, :w]))


#: a start whose mean |component| reaches this share of the image diagonal is warped out (calc_warped); a smaller
#: one is DIS's initial flow, which DIS keeps at small motions (13 px at 384 × 512)
WARP_MIN = 0.02


def warped_out(start: np.ndarray) -> bool:
    """Whether :func:`calc_deep` warps a start (H, W, 2) out (:func:`calc_warped`) rather than hand it to DIS as
    its initial flow: its mean |component| reaches :data:`WARP_MIN` of the image diagonal."""
    return float(np.abs(start).mean()) >= WARP_MIN * math.hypot(*start.shape[:2])


def calc_warped(objects, gray_i: np.ndarray, gray_j: np.ndarray, start: np.ndarray, level: int) -> np.ndarray:
    """DIS flow gray_i → gray_j from a start f₀: f₀ plus the flow r that DIS finds to gray_j warped back by f₀,

        r = DIS(I_i, I_j(x + f₀(x))),    f(x) = r(x) + f₀(x + r(x)).

    Handed to DIS as its initial flow, a start is only where the coarsest level begins: DIS searches
    again at every level, and under a large expansion (a camera travelling into the scene, the patches
    growing from frame to frame) it lost even an exact start (``drive`` preset, frames 10 → 14 at
    800 × 240: median error 1.2 px, 35 % of pixels over 3 px).  The warp takes the motion, expansion
    included, off the images, and DIS only measures what the start missed (0.17 px, 14 %, the rest
    mostly what the warp cannot show: pixels leaving the view or coming from behind a nearer surface).
    Where the start leads out of the image the warped image repeats its border, so there the flow is the
    start itself (its confidence is zero anyway, :func:`~droidw_cli.correspondence.confidence.inside_mask`;
    a flow made up from the repeated border read as motion to the epipolar masks).
    """
    maps = flow_map(start)
    warped = remap(gray_j, maps)
    residual = calc_deep(objects, gray_i, warped, None, level)
    residual[~inside_mask(start, maps)] = 0.0  # where the start leaves the image the warp shows nothing: keep it
    return np.ascontiguousarray(residual + sample_at_flow(start, residual), dtype=np.float32)


def to_gray(image: np.ndarray) -> np.ndarray:
    """(H, W) contiguous uint8 grayscale of an RGB (H, W, 3) or gray (H, W) uint8 image."""
    gray = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    return np.ascontiguousarray(gray)


class DISCorrespondence(CorrespondenceSource):
    """DIS optical flow with forward-backward and photometric confidence.

    Args:
        cfg: ``preset`` (ultrafast | fast | medium), ``fb_thresh`` (px) and
            ``photo_sigma`` (intensity in [0, 1]) are used.
    """

    name = "dis"
    concurrent_quick_target = True  # every thread has its own DIS objects
    concurrent_match = True

    def __init__(self, cfg: CorrespondenceConfig | None = None) -> None:
        cfg = cfg or CorrespondenceConfig()
        for key in ("preset", "quick_preset"):
            if getattr(cfg, key) not in PRESETS:
                raise ConfigError(f"correspondence.{key} '{getattr(cfg, key)}' is not one of: {', '.join(PRESETS)}")
        if not cfg.fb_thresh > 0:
            raise ConfigError(f"correspondence.fb_thresh must be > 0, got {cfg.fb_thresh}")
        if not cfg.photo_sigma > 0:
            raise ConfigError(f"correspondence.photo_sigma must be > 0, got {cfg.photo_sigma}")
        if not cfg.border_margin >= 0:
            raise ConfigError(f"correspondence.border_margin must be >= 0, got {cfg.border_margin}")
        if not 0 <= cfg.coarsest_scale <= 8:
            raise ConfigError(f"correspondence.coarsest_scale must be in 0..8 (0: DIS's own), got {cfg.coarsest_scale}")
        if not cfg.smoothness >= 0:
            raise ConfigError(f"correspondence.smoothness must be >= 0 (0: the preset's own), got {cfg.smoothness}")
        self.cfg = cfg
        self._local = threading.local()  # this thread's DIS objects (an OpenCV DIS object is not thread-safe)

    def _objects(self, name: str, smoothness: float = 0.0):
        """This thread's DIS objects of preset ``name`` (:func:`dis_objects`; an OpenCV DIS object is not
        thread-safe, so each thread, whichever runs a flow, has its own)."""
        return dis_objects(name, smoothness, self._local.__dict__.setdefault("dis", {}))

    def flow(self, gray_i: np.ndarray, gray_j: np.ndarray, init_flow: np.ndarray | None = None) -> np.ndarray:
        """(H, W, 2) float32 DIS flow gray_i → gray_j, optionally started from ``init_flow``."""
        start = None if init_flow is None else np.ascontiguousarray(init_flow, dtype=np.float32).copy()
        flow = calc_deep(self._objects(self.cfg.preset, self.cfg.smoothness), gray_i, gray_j, start, self.cfg.coarsest_scale)
        return np.ascontiguousarray(flow, dtype=np.float32)

    def _check(self, image_i: np.ndarray, image_j: np.ndarray, init_flow: np.ndarray | None) -> np.ndarray | None:
        validate_image(image_i, "image_i")
        validate_image(image_j, "image_j")
        if image_i.shape != image_j.shape:
            raise ValueError(f"image_i and image_j differ in shape: {image_i.shape} vs {image_j.shape}")
        return None if init_flow is None else validate_flow(init_flow, image_i.shape[:2])

    def _scored(self, gray_i: np.ndarray, gray_j: np.ndarray, fwd: np.ndarray, bwd: np.ndarray) -> Correspondence:
        conf = flow_confidence(gray_i, gray_j, fwd, bwd, self.cfg.fb_thresh, self.cfg.photo_sigma, self.cfg.border_margin)
        w = np.clip(area_downsample(conf), 0.0, 1.0)
        target = torch.from_numpy(flow_to_target(fwd))
        weight = torch.from_numpy(np.repeat(w[..., None], 2, axis=-1))
        return Correspondence(flow=fwd, target=target, weight=weight)

    def match(self, image_i: np.ndarray, image_j: np.ndarray, init_flow: np.ndarray | None = None) -> Correspondence:
        return self._one_after_the_other(MatchCall(image_i, image_j, init_flow))[0]

    def match_pair(self, image_i: np.ndarray, image_j: np.ndarray,
                   init_flow: np.ndarray | None = None) -> tuple[Correspondence, Correspondence]:
        """i → j and j → i from one forward-backward DIS pair (half the flow of two ``match`` calls)."""
        forward, backward = self._one_after_the_other(MatchCall(image_i, image_j, init_flow, both=True))
        return forward, backward

    def _one_after_the_other(self, call: MatchCall) -> list[Correspondence]:
        jobs, finish = self.stages(call)
        return [make() for make in finish([job() for job in jobs])]

    def stages(self, call):
        """Forward and backward flow as two jobs (the backward one started from the inverse of
        ``init_flow``), then the scoring of each correspondence (:meth:`CorrespondenceSource.stages`)."""
        init = self._check(call.image_i, call.image_j, call.init_flow)
        gray_i, gray_j = to_gray(call.image_i), to_gray(call.image_j)
        # the backward flow's start (the inverse of init_flow) is made in its job, off the calling thread
        jobs = [lambda: self.flow(gray_i, gray_j, init),
                lambda: self.flow(gray_j, gray_i, None if init is None else invert_flow(init))]

        def finish(outs):
            fwd, bwd = outs
            made = [lambda: self._scored(gray_i, gray_j, fwd, bwd)]
            if call.both:
                made.append(lambda: self._scored(gray_j, gray_i, bwd, fwd))
            return made
        return jobs, finish

    def quick_target(self, image_i: np.ndarray, image_j: np.ndarray) -> torch.Tensor:
        """Target i → j from one DIS flow (``quick_preset``) at the working resolution (no confidence)."""
        self._check(image_i, image_j, None)
        flow = calc_deep(self._objects(self.cfg.quick_preset), to_gray(image_i), to_gray(image_j), None,
                         self.cfg.coarsest_scale)
        return torch.from_numpy(flow_to_target(flow))

    def mean_flow(self, image_i: np.ndarray, image_j: np.ndarray) -> float:
        """Mean flow magnitude (full-res px) from FAST DIS on half-size grayscale images (cheap; for the motion filter)."""
        validate_image(image_i, "image_i")
        validate_image(image_j, "image_j")
        if image_i.shape != image_j.shape:
            raise ValueError(f"image_i and image_j differ in shape: {image_i.shape} vs {image_j.shape}")
        h, w = image_i.shape[:2]
        s = MEAN_FLOW_SCALE if min(h, w) >= 16 * MEAN_FLOW_SCALE else 1
        size = (w // s, h // s)
        small = [cv2.resize(to_gray(im), size, interpolation=cv2.INTER_AREA) for im in (image_i, image_j)]
        flow = calc_deep(self._objects(MEAN_FLOW_PRESET), small[0], small[1], None, level_at(self.cfg.coarsest_scale, s))
        return mean_length(flow) * s
