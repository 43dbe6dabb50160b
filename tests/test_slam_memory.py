"""What keeps a long run's memory flat: chunked end-of-run maps and compact per-keyframe storage."""

from __future__ import annotations

import numpy as np
import pypose as pp
import pytest
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.slam import frontend as frontend_mod
from droidw_cli.slam.frontend import Frontend

GRID = (6, 8)
K8 = torch.tensor([8.0, 8.0, 4.0, 3.0])


def _frontend_with_features(n: int, channels: int = 4) -> Frontend:
    """n keyframes along x with random features, neighbour and skip edges (noisy targets), and a random θ."""
    cfg = load_config("default", [])
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), None, GRID, K8, channels)
    g = torch.Generator().manual_seed(3)
    h, w = GRID
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    grid = torch.stack([xs, ys], -1)
    for k in range(n):
        w2c = pp.SE3(torch.tensor([-0.05 * k, 0, 0, 0, 0, 0, 1.0])).tensor().float()
        fe.buffer.append(k, k / 10.0, w2c, 0.5, np.zeros((2, 2, 3), np.uint8),
                         features=torch.randn(channels, h, w, generator=g))
        for j in (k - 1, k - 2):
            if j >= 0:
                for a, b in ((k, j), (j, k)):
                    fe.cache.put(a, b, grid + 0.3 * torch.randn(h, w, 2, generator=g),
                                 torch.rand(h, w, 2, generator=g))
    fe.shared.theta = 0.5 * torch.randn(fe.shared.theta.shape[0], generator=g)
    fe.initialised = True
    return fe


@pytest.mark.parametrize("chunk", [1, 7])
def test_uncertainty_with_chunked_evidence_equals_one_block(monkeypatch, chunk):
    fe = _frontend_with_features(23)
    fe.archive(0, 4)  # the oldest are frozen (float16), the live ones follow
    assert fe.evidence(4, 6) is not None  # the default config reads evidence maps
    monkeypatch.setattr(frontend_mod, "UNCERTAINTY_CHUNK", 10**6)
    whole = fe.uncertainty()
    monkeypatch.setattr(frontend_mod, "UNCERTAINTY_CHUNK", chunk)
    assert torch.equal(fe.uncertainty(), whole)
    assert torch.equal(fe.uncertainty(5, 17), whole[5:17])


def test_feature_block_converts_without_changing_values():
    fe = _frontend_with_features(5)
    block = fe.buffer.feature_block(1, 4, torch.float32)
    assert block.dtype == torch.float32 and torch.equal(block, fe.buffer.feature_block(1, 4).float())
