"""Grid conventions: full-res flow ↔ 1/8-grid targets, confidence primitives."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.correspondence.confidence import forward_backward_error, inside_mask, invert_flow, photometric_error
from droidw_cli.correspondence.grid import area_downsample, cached_grid, flow_to_target, grid_coordinates, target_to_flow


def test_area_downsample_is_the_block_mean():
    rng = np.random.default_rng(0)
    field = rng.standard_normal((16, 24, 2)).astype(np.float32)
    down = area_downsample(field)
    assert down.shape == (2, 3, 2)
    assert np.allclose(down[1, 2], field[8:16, 16:24].mean(axis=(0, 1)), atol=1e-6)
    assert area_downsample(field[..., 0]).shape == (2, 3)
    with pytest.raises(ValueError):
        area_downsample(field[:12])


def test_constant_flow_target_is_grid_plus_flow_over_8():
    flow = np.broadcast_to(np.float32([8.0, -4.0]), (16, 32, 2))
    t = flow_to_target(flow)
    g = grid_coordinates(2, 4)
    assert np.allclose(t, g + np.float32([1.0, -0.5]))


def test_target_uses_pixel_centre_convention():
    """An affine flow's block mean equals its value at the block centre 8g + 3.5."""
    h, w = 32, 48
    a = np.float32([[0.05, 0.01], [-0.02, 0.03]])
    x = grid_coordinates(h, w)
    flow = (x @ a.T + np.float32([2.0, 1.0])).astype(np.float32)
    centre = 8 * grid_coordinates(h // 8, w // 8) + 3.5
    expected = (centre + centre @ a.T + np.float32([2.0, 1.0]) - 3.5) / 8
    assert np.allclose(flow_to_target(flow), expected, atol=1e-4)


def test_target_to_flow_round_trip_for_affine_flow():
    h, w = 32, 48
    a = np.float32([[0.05, 0.01], [-0.02, 0.03]])
    flow = (grid_coordinates(h, w) @ a.T + np.float32([2.0, 1.0])).astype(np.float32)
    target = torch.from_numpy(flow_to_target(flow))
    back = target_to_flow(target)
    assert back.shape == (h, w, 2) and back.dtype == np.float32
    assert np.allclose(back[4:-4, 4:-4], flow[4:-4, 4:-4], atol=1e-4)
    with pytest.raises(ValueError):
        target_to_flow(np.zeros((4, 6)))


def test_grid_coordinates_are_fresh_copies_of_a_read_only_cache():
    g = grid_coordinates(3, 5)
    assert g.shape == (3, 5, 2) and g[2, 4, 0] == 4 and g[2, 4, 1] == 2
    g[0, 0, 0] = 7.0  # writable, and does not corrupt the cache
    assert grid_coordinates(3, 5)[0, 0, 0] == 0.0
    cached = cached_grid(3, 5)
    assert cached_grid(3, 5) is cached
    with pytest.raises(ValueError):
        cached[0, 0, 0] = 1.0


def test_forward_backward_and_inverse():
    h, w = 16, 24
    fwd = np.broadcast_to(np.float32([2.0, 1.0]), (h, w, 2)).copy()
    assert np.allclose(forward_backward_error(fwd, -fwd), 0.0)
    assert np.allclose(forward_backward_error(fwd, fwd), np.hypot(4, 2), atol=1e-5)
    assert np.allclose(invert_flow(fwd), -fwd)


def test_inside_mask_and_photometric_error():
    h, w = 16, 24
    flow = np.zeros((h, w, 2), np.float32)
    flow[..., 0] = 3.0
    inside = inside_mask(flow)
    assert inside[:, : w - 3].all() and not inside[:, w - 3 :].any()
    gray = np.tile(np.arange(w, dtype=np.uint8) * 10, (h, 1))
    err = photometric_error(gray, gray, flow)
    assert np.allclose(err[:, : w - 3], 30 / 255, atol=1e-5)
