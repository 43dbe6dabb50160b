"""The pipeline hands the BA backend tensors on ``backend.device`` only (issue 10), without a GPU.

A spy backend reports the device ``cuda`` and checks that every tensor of every
call is on it; the run happens inside :class:`fake_device.FakeCuda`, which
makes ``device="cuda"`` tensors ordinary CPU tensors with a tag and refuses to
mix them with host tensors the way CUDA does.  The spy computes with the CPU
backend on host copies, so the run must also give exactly the trajectory of a
plain CPU run: keeping tensors on the backend's device changes nothing else.
"""

from __future__ import annotations

from collections import Counter

import numpy as np
import pytest
import torch

from droidw_cli.ba.interface import BABackend
from droidw_cli.ba.types import BAState, BAStepResult, EdgeSet, UncertaintyStepResult
from droidw_cli.config import load_config
from droidw_cli.correspondence import get_correspondence_source
from droidw_cli.features import get_feature_extractor
from droidw_cli.io.input import open_source
from droidw_cli.slam.tracker import Tracker
from droidw_cli.synth import SynthConfig, write_sequence
from droidw_backend_cpu import CpuBackend
from fake_device import FakeCuda, is_fake

# a 30 × 40 grid, keyframes at half the default spacing (as in test_track_dynamic.py), every stage on
# (uncertainty, evidence maps, epipolar masks, global BA, filler with its stride) with few iterations each
OVERRIDES = ["io.target_area=76800", "motion_filter.thresh=1.5", "frontend.keyframe_thresh=1.5",
             "frontend.init_iters=6", "uncertainty.warmup_iters=2", "backend.iters=3", "filler.iters=2",
             "filler.stride=2"]


class SpyBackend(BABackend):
    """Checks every tensor input against ``device``; computes with the CPU backend on host copies."""

    name = "spy"

    def __init__(self, mode: FakeCuda) -> None:
        self.inner = CpuBackend()
        self.mode = mode
        self.calls: Counter[str] = Counter()

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        return True, "test spy"

    @property
    def device(self) -> torch.device:
        return self.mode.device

    def _check(self, method: str, **inputs) -> None:
        self.calls[method] += 1
        for name, value in inputs.items():
            fields = value.__dict__.items() if isinstance(value, (BAState, EdgeSet)) else [("", value)]
            for field, t in fields:
                if isinstance(t, torch.Tensor) and t.device.type != self.device.type:
                    raise AssertionError(f"{method}: {name}.{field} is on {t.device}, not on backend.device "
                                         f"{self.device}")

    def reproject(self, state, ii, jj, min_depth=0.05):
        self._check("reproject", state=state, ii=ii, jj=jj)
        host, ii, jj = state.to("cpu"), ii.cpu(), jj.cpu()
        with self.mode.suspended():
            coords, valid = self.inner.reproject(host, ii, jj, min_depth)
        return coords.to(self.device), valid.to(self.device)

    def ba_step(self, state, edges, params):
        self._check("ba_step", state=state, edges=edges)
        host, host_edges = state.to("cpu"), edges.to("cpu")
        with self.mode.suspended():
            r = self.inner.ba_step(host, host_edges, params)
        return BAStepResult(r.state.to(self.device), r.cost, r.solved)

    def uncertainty_step(self, state, edges, params):
        self._check("uncertainty_step", state=state, edges=edges)
        host, host_edges = state.to("cpu"), edges.to("cpu")
        with self.mode.suspended():
            r = self.inner.uncertainty_step(host, host_edges, params)
        return UncertaintyStepResult(r.theta.to(self.device), r.loss)


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    cfg = SynthConfig.preset("dynamic", width=320, height=240, frames=30, seed=1, camera_speed=2.5)
    return write_sequence(cfg, tmp_path_factory.mktemp("dev") / "seq", progress=False)


def _track(seq, backend):
    cfg = load_config("default", OVERRIDES)
    source = open_source(seq)
    features = get_feature_extractor(cfg.features.name)
    torch.manual_seed(cfg.seed)
    return Tracker(cfg, backend, get_correspondence_source(cfg.correspondence), features,
                   progress=False).run(source, source.intrinsics_hint)


def test_fake_device_refuses_a_host_tensor():
    with FakeCuda():
        a = torch.zeros(3, device="cuda")
        assert is_fake(a) and a.device.type == "cuda"
        with pytest.raises(RuntimeError, match="same device"):
            a + torch.ones(3)
        assert not is_fake(a.cpu()) and is_fake(a + torch.tensor(1.0))  # host 0-d tensors pass, as on CUDA


def test_pipeline_keeps_backend_tensors_on_backend_device(clip, one_torch_thread):
    mode = FakeCuda()
    spy = SpyBackend(mode)
    with mode:
        on_device = _track(clip, spy)
    assert on_device.initialised
    assert min(spy.calls[m] for m in ("reproject", "ba_step", "uncertainty_step")) > 0, spy.calls
    plain = _track(clip, CpuBackend())
    np.testing.assert_array_equal(on_device.poses_c2w, plain.poses_c2w)
    np.testing.assert_array_equal(on_device.kf_disps, plain.kf_disps)
    np.testing.assert_array_equal(on_device.kf_uncertainty, plain.kf_uncertainty)
