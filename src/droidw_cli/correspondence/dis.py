"""Correspondences from OpenCV's DIS optical flow (Kroeger et al., ECCV 2016).

``match`` runs DIS i → j and j → i on grayscale images, scores each pixel
(:mod:`droidw_cli.correspondence.confidence`) and brings flow and weight to
the 1/8 grid by block averaging (:mod:`droidw_cli.correspondence.grid`).
With ``init_flow`` the forward pass starts from it and the backward pass
from its approximate inverse; DIS uses a passed-in float32 (H, W, 2) flow as
its initialisation, which makes ~100 px motions recoverable.

DIS is deterministic, also across thread counts (its spatial propagation
uses a fixed number of stripes).
"""

from __future__ import annotations

import threading

import cv2
import numpy as np
import torch

from droidw_cli.config import CorrespondenceConfig
from droidw_cli.correspondence.base import Correspondence, CorrespondenceSource, MatchCall
from droidw_cli.correspondence.confidence import flow_confidence, invert_flow
from droidw_cli.correspondence.grid import area_downsample, flow_to_target, validate_flow, validate_image
from droidw_cli.errors import ConfigError

#: name → (OpenCV preset, overrides).  ``fine`` is FAST with its finest pyramid level at 1/2
#: instead of 1/4 of the working size and a sparser patch grid: about FAST's cost, and on a
#: 384 × 512 walk frame pair 0.04 px median deviation from a long MEDIUM run against FAST's 0.15.
PRESETS = {
    "ultrafast": (cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST, {}),
    "fast": (cv2.DISOPTICAL_FLOW_PRESET_FAST, {}),
    "fine": (cv2.DISOPTICAL_FLOW_PRESET_FAST, {"FinestScale": 1, "PatchStride": 6}),
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

# mean_flow runs FAST DIS at 1/2 resolution: about 3 ms at 448×592 here.  ULTRAFAST at 1/4
# (0.6 ms) reads 1-3 px of spurious mean flow on a static-camera clip (vtest), too close
# to the motion filter's 3 px threshold; FAST at 1/2 reads 0.3-1.4 px there.
MEAN_FLOW_SCALE = 2
MEAN_FLOW_PRESET = "fast"
# quick_target (the filler's flow, correspondence.quick_preset): one direction at the working
# resolution.  At half resolution the filler's camera centres were 2-3× worse on the generator's
# walks; "fine" instead of "fast" took the 600-frame static control from 0.51 to 0.34 cm.


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
        if not cfg.smoothness >= 0:
            raise ConfigError(f"correspondence.smoothness must be >= 0 (0: the preset's own), got {cfg.smoothness}")
        self.cfg = cfg
        self._local = threading.local()  # this thread's DIS objects (an OpenCV DIS object is not thread-safe)

    def _dis_of(self, name: str, seeded: bool = False, smoothness: float = 0.0):
        """This thread's DIS object of preset ``name`` and ``smoothness`` (:func:`create_dis`), for flows
        with (``seeded``) or without an initial flow.

        OpenCV's DIS keeps state between calls: a call without an initial flow that follows one
        with an initial flow starts from a leftover of it (up to 4 px difference on a walk pair
        with MEDIUM), so calls with and without one use separate objects.  Otherwise DIS keeps
        nothing between calls, so each result depends on its inputs only, whichever thread runs it.
        """
        objects = self._local.__dict__.setdefault("dis", {})
        key = (name, seeded, smoothness)
        if key not in objects:
            objects[key] = create_dis(name, smoothness)
        return objects[key]

    def flow(self, gray_i: np.ndarray, gray_j: np.ndarray, init_flow: np.ndarray | None = None) -> np.ndarray:
        """(H, W, 2) float32 DIS flow gray_i → gray_j, optionally started from ``init_flow``."""
        if init_flow is None:
            dis = self._dis_of(self.cfg.preset, smoothness=self.cfg.smoothness)
            return np.ascontiguousarray(dis.calc(gray_i, gray_j, None), dtype=np.float32)
        start = np.ascontiguousarray(init_flow, dtype=np.float32).copy()
        flow = self._dis_of(self.cfg.preset, seeded=True, smoothness=self.cfg.smoothness).calc(gray_i, gray_j, start)
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
        flow = self._dis_of(self.cfg.quick_preset).calc(to_gray(image_i), to_gray(image_j), None)
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
        flow = self._dis_of(MEAN_FLOW_PRESET).calc(small[0], small[1], None)
        return float(np.linalg.norm(flow, axis=-1).mean() * s)
