"""RGB-D mode: keyframe disparities start from the sensor, so the metric scale is there from the first BA step."""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.slam.depth_prior import grid_disparity, seed_disparity
from droidw_cli.slam.frontend import Frontend

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


def test_grid_disparity_is_the_plane_at_each_cell_centre():
    """A tilted plane has disparity affine in the image: the grid value is exact at 8u + 3.5, holes give 0."""
    h, w = GRID
    v, u = np.mgrid[0 : 8 * h, 0 : 8 * w].astype(np.float64)
    plane = lambda x, y: 0.2 + 0.004 * x + 0.009 * y  # noqa: E731  disparity of a plane seen from the camera
    depth = (1.0 / plane(u, v)).astype(np.float32)
    depth[19, 36] = 0.0  # one invalid pixel at the centre of cell (2, 4)
    d = grid_disparity(depth, GRID)
    cv, cu = np.mgrid[0:h, 0:w] * 8 + 3.5
    expected = torch.from_numpy(plane(cu, cv).astype(np.float32))
    expected[2, 4] = 0.0
    assert d.shape == GRID and d.dtype == torch.float32
    assert torch.allclose(d, expected, rtol=1e-4, atol=1e-6)
    # the block's first pixel (OpenCV's nearest neighbour) is 3.5 px off: a visible bias on this plane
    first = torch.from_numpy(plane(cu - 3.5, cv - 3.5).astype(np.float32))
    assert float((first - expected).abs().max()) > 0.04


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
