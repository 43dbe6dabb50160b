"""RGB-D mode: keyframe disparities start from the sensor, so the metric scale is there from the first BA step."""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.slam.frontend import Frontend, seed_disparity

GRID = (6, 8)
K8 = torch.tensor([10.0, 10.0, 3.5, 2.5])


def test_seed_takes_the_sensor_where_valid_and_the_fallback_elsewhere():
    prior = torch.full(GRID, 0.4)
    prior[0, :3] = 0.0  # invalid sensor depth
    fallback = torch.full(GRID, 0.9)
    d = seed_disparity(fallback, prior, GRID)
    assert torch.allclose(d[prior > 0], torch.tensor(0.4))
    assert torch.allclose(d[0, :3], torch.tensor(0.9))
    assert torch.equal(seed_disparity(1.0, None, GRID), torch.ones(GRID))


def test_first_keyframe_disparity_is_the_sensor_disparity():
    cfg = load_config("rgbd", ["uncertainty.enable=false", "dynamics.mode=none", "frontend.warmup=50"])
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), None, GRID, K8, 0)
    image = np.full((GRID[0] * 8, GRID[1] * 8, 3), 128, np.uint8)
    prior = torch.full(GRID, 1.0 / 2.5)  # a wall 2.5 m away
    prior[2, 2] = 0.0
    fe.add_keyframe(0, 0.0, image, image[::8, ::8], None, prior)
    d = fe.buffer.disps[0]
    assert torch.allclose(d[prior > 0], torch.tensor(0.4))  # not the scale-free guess 1.0 (1 m)
    assert float(d[2, 2]) == 1.0  # no sensor depth: the fallback
