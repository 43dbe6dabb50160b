"""Frontend.doomed (``frontend.skip_doomed``): a candidate that keyframe removal would drop at once is
passed over, decided from the motion filter's flow and the translation of the extrapolated pose."""

from __future__ import annotations

from types import SimpleNamespace

import cv2
import numpy as np
import pytest
import torch

from droidw_cli.config import FrontendConfig, MotionFilterConfig, load_config
from droidw_cli.slam.frontend import Frontend
from droidw_cli.slam.motion_filter import MotionFilter
from droidw_cli.slam.scout import Scout

H, W, F = 24, 32, 60.0  # grid, focal (grid px)


class _Buffer(SimpleNamespace):
    def __len__(self) -> int:
        return len(self.frame_index)


def _frontend(frames=(0, 4), step: float = 0.04, **overrides) -> SimpleNamespace:
    """Keyframes at ``frames``; the camera moves ``step`` m along x from one to the next, facing a
    fronto-parallel plane at 1 m (disparity 1)."""
    poses = torch.zeros(len(frames), 7)
    poses[:, 6] = 1.0
    poses[:, 0] = -step * torch.arange(len(frames))  # world-to-camera: t = −camera position
    cfg = FrontendConfig(**{"skip_doomed": True, "beta": 0.5, "keyframe_thresh": 3.0, "removal_max_span": 12,
                            "proximity_stride": 1, **overrides})
    buffer = _Buffer(frame_index=list(frames), poses=poses, disps=torch.ones(len(frames), H, W), device="cpu")
    return SimpleNamespace(fcfg=cfg, buffer=buffer, initialised=True, params=SimpleNamespace(min_depth=0.05),
                           shared=SimpleNamespace(intrinsics=torch.tensor([F, F, W / 2, H / 2])))


def test_the_prediction_mixes_the_filter_flow_with_the_extrapolated_translation():
    """Frame 6 after keyframes 0 and 4 (4 cm apart): the pose extrapolated by α = 2/4 lies 2 cm on,
    whose translation-only flow on the plane at 1 m is f · 0.02 = 1.2 grid px; d̂ = ½ full + ½ · 1.2."""
    fe = _frontend()
    assert Frontend.doomed(fe, 6, 4.6)  # d̂ = 2.9 < 3
    assert not Frontend.doomed(fe, 6, 5.0)  # d̂ = 3.1
    fast = _frontend(step=0.2)  # 10 cm on by frame 6: 6 grid px of parallax alone
    assert not Frontend.doomed(fast, 6, 0.0)


def test_nothing_is_skipped_off_before_initialisation_or_past_half_the_removal_span():
    assert not Frontend.doomed(_frontend(skip_doomed=False), 6, 0.0)
    early = _frontend()
    early.initialised = False
    assert not Frontend.doomed(early, 6, 0.0)
    assert not Frontend.doomed(_frontend(frames=(4,)), 6, 0.0)  # one keyframe: no velocity
    fe = _frontend()
    assert Frontend.doomed(fe, 10, 0.0)  # 6 frames on: the next candidate may still come within 12
    assert not Frontend.doomed(fe, 11, 0.0)


def test_skip_doomed_is_on_for_fast_only():
    assert not load_config("default").frontend.skip_doomed and not load_config("rgbd").frontend.skip_doomed
    assert load_config("fast").frontend.skip_doomed


def test_the_scout_hands_each_candidates_flow_over_once():
    """The flow of a candidate is the motion filter's mean flow from the previous candidate (grid px)."""
    rng = np.random.default_rng(0)
    big = cv2.GaussianBlur(cv2.resize(rng.integers(0, 255, (72, 104), dtype=np.uint8), (832, 576)), (5, 5), 1.0)
    shifts = [0, 0, 30, 60, 65, 95]  # px at the working size; 24 px = 3 grid px, the filter's threshold
    frames = [np.ascontiguousarray(np.repeat(big[:384, s:s + 512, None], 3, axis=2)) for s in shifts]
    scout = Scout(MotionFilter(MotionFilterConfig(max_gap=9)))
    scout.taken(initialised=True)
    flagged = [f.index for f, _, _, kf in scout.frames((SimpleNamespace(index=i), im, None)
                                                 for i, im in enumerate(frames)) if kf]
    assert flagged == [0, 2, 3, 5]
    flows = [scout.flow(i) for i in flagged]
    assert flows[0] == 0.0  # the first frame
    for got, px in zip(flows[1:], (30, 30, 35)):
        assert got == pytest.approx(px / 8, rel=0.15)
    assert scout.flow(2) == 0.0  # handed over once
