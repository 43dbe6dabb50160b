"""The bounded global backend: loop (proximity) edges on a revisit, the horizon, stored keyframe images; the
frontend's proximity pairs under fast motion."""

from __future__ import annotations

import numpy as np
import pypose as pp
import pytest
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.correspondence.base import CorrespondenceSource
from droidw_cli.slam.backend import GlobalBackend, KeyframeImages
from droidw_cli.slam.distance import frame_distance
from droidw_cli.slam.frontend import Frontend

GRID = (24, 32)
K8 = torch.tensor([30.0, 30.0, 16.0, 12.0])


class _NoMatch(CorrespondenceSource):
    """A correspondence source that records the pairs it is asked for and returns exact-looking targets."""

    def __init__(self):
        self.asked = []

    def match_pair(self, image_i, image_j, init_flow=None):
        self.asked.append("pair")
        return self._corr(), self._corr()

    def match(self, image_i, image_j, init_flow=None):
        self.asked.append("one")
        return self._corr()

    @staticmethod
    def _corr():
        from droidw_cli.correspondence.base import Correspondence
        h, w = GRID
        ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
        return Correspondence(flow=np.zeros((h * 8, w * 8, 2), np.float32), target=torch.stack([xs, ys], -1),
                              weight=torch.full((h, w, 2), 0.5))


def _loop_frontend(n: int, sets=()):
    """n keyframes on a circle of radius 0.5 m, looking outwards at a wall 3 m away: the last ones revisit the first."""
    cfg = load_config("default", ["uncertainty.enable=false", *sets])
    corr = _NoMatch()
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), corr, GRID, K8, 0)
    image = np.full((GRID[0] * 8, GRID[1] * 8, 3), 128, np.uint8)
    for k in range(n):
        yaw = 2 * np.pi * k / (n - 1)
        c, s = np.cos(yaw / 2), np.sin(yaw / 2)
        q = torch.tensor([0.0, s, 0.0, c])  # rotation about y (camera-to-world)
        c2w = pp.SE3(torch.cat([torch.zeros(3), q]))
        w2c = c2w.Inv().tensor().float()
        fe.buffer.append(k, k / 10.0, w2c, 1.0 / 3.0, image[::8, ::8])
        fe.images[k] = image
        if k:
            fe.cache.put(k, k - 1, *(t for t in (_NoMatch._corr().target, _NoMatch._corr().weight)))
            fe.cache.put(k - 1, k, _NoMatch._corr().target, _NoMatch._corr().weight)
    fe.initialised = True
    return fe, cfg, corr


def test_loop_edges_join_a_revisit_and_nothing_near_the_frontend_edges():
    fe, cfg, corr = _loop_frontend(24, ["backend.every=0", "backend.iters=1"])
    gba = GlobalBackend(fe, cfg.backend)
    for k in range(24):
        gba.images.put(k, fe.images[k])
    gba.run(1)
    new = {p for p in fe.cache.pairs() if abs(p[0] - p[1]) > 1}
    assert new, "the closing of the circle must bring proximity edges"
    assert all(abs(i - j) > 5 for i, j in new)  # nms 5 around the frontend's neighbour edges
    assert any({i, j} & {0, 1, 2} and {i, j} & {21, 22, 23} for i, j in new)  # first and last views meet
    assert gba.loop_edges == len(new)


def test_the_horizon_drops_old_edges_and_images():
    fe, cfg, _ = _loop_frontend(24, ["backend.every=0", "backend.iters=1", "backend.horizon=10", "frontend.window=8"])
    gba = GlobalBackend(fe, cfg.backend)
    for k in range(24):
        gba.images.put(k, fe.images[k])
    before = fe.buffer.poses[:14].clone()
    gba.run(1)
    assert gba.lo == 14
    assert all(min(p) >= 14 for p in fe.cache.pairs())
    assert len(gba.images) == 10
    assert torch.equal(fe.buffer.poses[:14], before)  # keyframes that left the problem keep their poses


def test_keyframe_images_round_trip_close_to_the_original():
    rng = np.random.default_rng(0)
    import cv2
    noise = cv2.GaussianBlur((rng.random((64, 96, 3)) * 255).astype(np.float32), (0, 0), 2.0)  # an image-like texture
    image = np.clip(noise + np.linspace(-60, 60, 96)[None, :, None], 0, 255).astype(np.uint8)
    store = KeyframeImages(95)
    store.put(7, image)
    back = store.get(7)
    assert back.shape == image.shape and back.dtype == np.uint8
    assert np.abs(back.astype(int) - image.astype(int)).mean() < 4.0
    assert store.nbytes < image.nbytes / 2
    store.keep({8})
    assert len(store) == 0


def test_strided_frame_distance_matches_the_full_grid():
    torch.manual_seed(0)
    n = 12
    poses = torch.zeros(n, 7)
    poses[:, 6] = 1.0
    poses[:, :3] = torch.randn(n, 3) * 0.05
    disps = torch.nn.functional.avg_pool2d(torch.rand(n, 1, 48, 64), 9, 1, 4)[:, 0] + 0.5
    k = torch.tensor([60.0, 60.0, 32.0, 24.0])
    ii, jj = torch.arange(0, n - 1), torch.arange(1, n)
    full = frame_distance(poses, disps, k, ii, jj)
    coarse = frame_distance(poses, disps, k, ii, jj, stride=4)
    assert torch.allclose(coarse, full, rtol=0.1)


def test_the_global_ba_runs_on_its_own_thread_count_and_restores_the_callers(monkeypatch):
    """The global BA runs while the frontend's workers idle, so it gets every usable core (runtime/threads.py)."""
    import droidw_cli.slam.backend as backend_module

    fe, cfg, _ = _loop_frontend(12, ["backend.every=0", "backend.iters=1"])
    seen = []
    real = backend_module.run_window

    def recording(*args, **kwargs):
        seen.append(torch.get_num_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(backend_module, "run_window", recording)
    before = torch.get_num_threads()
    GlobalBackend(fe, cfg.backend, threads=3).run(1)
    GlobalBackend(fe, cfg.backend).run(1)  # 0: the caller's count
    assert seen == [3, before]
    assert torch.get_num_threads() == before


def test_torch_threads_leave_a_core_to_the_workers_except_when_alone(monkeypatch):
    import droidw_cli.runtime.threads as threads

    for cores, busy, alone in [(1, 1, 1), (2, 1, 2), (4, 3, 4), (16, 8, 8)]:
        monkeypatch.setattr(threads, "usable_cores", lambda c=cores: c)
        assert threads.torch_threads(0) == busy and threads.torch_threads(0, alone=True) == alone
    assert threads.torch_threads(5) == 5 and threads.torch_threads(5, alone=True) == 5  # asked for: kept
    before = torch.get_num_threads()
    try:
        with threads.torch_threads_set(2):
            assert torch.get_num_threads() == 2
            raise RuntimeError
    except RuntimeError:
        pass
    assert torch.get_num_threads() == before


def _still_frontend(n: int, spacing: int, sets=()):
    """n keyframes ``spacing`` frames apart, 1 cm apart in x: every pair is well under the proximity threshold."""
    cfg = load_config("default", ["uncertainty.enable=false", *sets])
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), _NoMatch(), GRID, K8, 0)
    image = np.full((GRID[0] * 8, GRID[1] * 8, 3), 128, np.uint8)
    for k in range(n):
        fe.buffer.append(k * spacing, k * spacing / 30.0, torch.tensor([-0.01 * k, 0, 0, 0, 0, 0, 1.0]), 1.0 / 3.0,
                         image[::8, ::8])
    fe.initialised = True
    return fe


@pytest.mark.parametrize("spacing, pairs", [(2, 1), (3, 1), (4, 3), (9, 3)])
def test_a_keyframe_close_behind_its_predecessor_brings_one_proximity_pair(spacing, pairs):
    """frontend.proximity_gap (4 frames): fast motion brings keyframes every few frames, each with one pair."""
    fe = _still_frontend(20, spacing)
    got = fe._proximity(19, 0)
    assert len(got) == 2 * pairs and all((j, i) in got for i, j in got)
    assert len(_still_frontend(20, spacing, ["frontend.proximity_gap=0"])._proximity(19, 0)) == 6  # the old rule
