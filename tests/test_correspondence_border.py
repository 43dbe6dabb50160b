"""The correspondence border margin: DIS's flow is biased near the image border, so pixels
(and targets) within ``correspondence.border_margin`` px of it get no weight."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from droidw_cli.config import CorrespondenceConfig, load_config
from droidw_cli.correspondence import DISCorrespondence
from droidw_cli.correspondence.confidence import inside_mask, zero_border
from droidw_cli.errors import ConfigError
from test_correspondence_dis import H, W, expected_target, texture, warp


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return texture(H, W, 3)


def test_zero_border_clears_ceil_margin_rows_and_columns():
    w = np.ones((10, 12), np.float32)
    zero_border(w, 2.5)
    assert np.all(w[:3] == 0) and np.all(w[-3:] == 0) and np.all(w[:, :3] == 0) and np.all(w[:, -3:] == 0)
    assert np.all(w[3:-3, 3:-3] == 1)
    untouched = np.ones((4, 4), np.float32)
    assert np.all(zero_border(untouched, 0.0) == 1)


def test_inside_mask_margin_shrinks_the_image_on_every_side():
    flow = np.zeros((40, 48, 2), np.float32)
    flow[..., 0] = 3.0  # everything moves 3 px right
    m = inside_mask(flow, margin=8.0)
    cols = np.flatnonzero(m[20])
    # x + 3 >= 7.5 and x + 3 <= 48 - 0.5 - 8
    assert cols[0] == 5 and cols[-1] == 36
    rows = np.flatnonzero(m[:, 20])
    assert rows[0] == 8 and rows[-1] == 31
    assert np.array_equal(inside_mask(flow), inside_mask(flow, margin=0.0))


def test_dis_flow_near_the_border_is_biased_towards_the_interior(image):
    """Under a zoom the flow grows towards the border; DIS reads it short there (why the margin exists)."""
    m = cv2.getRotationMatrix2D((W / 2, H / 2), 0.0, 1.04).astype(np.float32)
    corr = DISCorrespondence(CorrespondenceConfig(preset="medium")).match(image, warp(image, m))
    h, w = H // 8, W // 8
    exp = expected_target(m, H, W)
    grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1)
    true_flow, got_flow = exp - grid, corr.target.numpy() - grid
    ring = np.minimum(np.minimum(np.arange(h)[:, None], h - 1 - np.arange(h)[:, None]),
                      np.minimum(np.arange(w)[None], w - 1 - np.arange(w)[None]))

    def scale(sel):
        return float((got_flow[sel] * true_flow[sel]).sum() / (true_flow[sel] ** 2).sum())

    assert scale(ring == 0) < scale((ring >= 3) & (ring <= 6)) - 0.01


def test_border_margin_zeroes_source_and_target_cells(image):
    m = np.float32([[1, 0, 12], [0, 1, 0]])  # 12 px to the right
    j = warp(image, m)
    plain = DISCorrespondence().match(image, j).weight[..., 0].numpy()
    cut = DISCorrespondence(CorrespondenceConfig(border_margin=16.0)).match(image, j).weight[..., 0].numpy()
    # source side: the outer two cell rings (16 px) are zero
    assert np.all(cut[:2] == 0) and np.all(cut[-2:] == 0) and np.all(cut[:, :2] == 0)
    # target side: pixels whose target lands within 16 px of the right border (x + 12 > W − 16.5,
    # x ≥ 292) have none: cells 37-39 entirely, cell 36 (x = 288 … 295) half
    assert np.all(cut[:, -3:] == 0)
    assert np.all(cut[3:-3, -4] < 0.6 * plain[3:-3, -4] + 1e-6)
    inner = (slice(3, -3), slice(3, -5))
    assert np.allclose(cut[inner], plain[inner], atol=0.02)
    assert cut[inner].mean() > 0.8


def test_negative_margin_is_a_config_error():
    with pytest.raises(ConfigError, match="border_margin"):
        DISCorrespondence(CorrespondenceConfig(border_margin=-1.0))


def test_rgbd_config_sets_a_border_margin():
    assert load_config("rgbd").correspondence.border_margin >= 16
