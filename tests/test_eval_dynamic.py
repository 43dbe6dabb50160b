"""AUROC and ground-truth masks on the BA grid."""

import cv2
import numpy as np
import pytest

from droidw_cli.eval.dynamic import auroc, masks_on_grid


def test_auroc_known_values():
    assert auroc(np.array([0.1, 0.2, 0.8, 0.9]), np.array([0, 0, 1, 1])) == 1.0
    assert auroc(np.array([0.9, 0.8, 0.2, 0.1]), np.array([0, 0, 1, 1])) == 0.0
    assert auroc(np.ones(6), np.array([0, 1, 0, 1, 0, 1])) == 0.5  # ties count half
    rng = np.random.default_rng(0)
    y = rng.random(4000) < 0.3
    s = rng.normal(size=4000) + 1.0 * y  # d' = 1 → AUROC = Φ(1/√2) ≈ 0.760
    assert auroc(s, y) == pytest.approx(0.760, abs=0.02)
    assert np.isnan(auroc(np.arange(3), np.zeros(3)))


def test_masks_follow_the_frame_preparation(tmp_path):
    m = np.zeros((240, 320), np.uint8)
    m[:, :160] = 255  # left half dynamic
    p = tmp_path / "m.png"
    cv2.imwrite(str(p), m)
    grid = masks_on_grid([p], (240, 320), 76800)
    assert grid.shape == (1, 30, 40)
    assert grid[0, :, :20].all() and not grid[0, :, 20:].any()
