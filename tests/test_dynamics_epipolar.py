"""Epipolar motion segmentation: Sampson distance, the fitted geometry, and the keyframe mask."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.dynamics.epipolar import (NOISE_FACTOR, block_centres, epipolar_distance, moving_mask,
                                          sampson_distance)

H, W = 96, 128  # working resolution; the grid is 12 × 16
K = np.array([[100.0, 0.0, 63.5], [0.0, 100.0, 47.5], [0.0, 0.0, 1.0]])


def _skew(t):
    return np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])


def _rigid_flow(depth: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(H, W, 2) flow of a pure translation t of the camera over a scene at ``depth`` (H, W)."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.linalg.inv(K) @ np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    pts = rays * depth.ravel() - t[:, None]
    proj = K @ pts
    u, v = proj[0] / proj[2], proj[1] / proj[2]
    return np.stack([u - xs.ravel(), v - ys.ravel()], 1).reshape(H, W, 2).astype(np.float32)


def _scene():
    ys, xs = np.mgrid[0:H, 0:W]
    depth = 2.0 + 1.5 * np.sin(xs / 17.0) * np.cos(ys / 13.0) + 0.01 * xs  # varied depth: F is well determined
    t = np.array([0.12, 0.03, 0.02])
    flow = _rigid_flow(depth, t)
    mover = np.zeros((H, W), bool)
    mover[24:56, 32:64] = True  # grid cells rows 3-6, cols 4-7
    flow[mover] += np.array([0.0, 6.0], np.float32)  # moves 6 px down, across the near-horizontal epipolar lines
    return flow, mover, t


def test_sampson_distance_is_zero_on_the_epipolar_line_and_the_offset_across_it():
    e_mat = _skew(np.array([1.0, 0.0, 0.0]))  # F of a pure x-translation with K = I: epipolar lines are horizontal
    x_i = np.array([[10.0, 5.0], [3.0, -2.0]])
    on_line = x_i + np.array([[4.0, 0.0], [-7.0, 0.0]])
    assert np.allclose(sampson_distance(e_mat, x_i, on_line), 0.0)
    off = x_i + np.array([[4.0, 1.0], [0.0, -3.0]])
    # Sampson distance of a vertical offset δ between two horizontal lines: |δ| / √2
    assert np.allclose(sampson_distance(e_mat, x_i, off), np.array([1.0, 3.0]) / np.sqrt(2.0))


def test_block_centres_follow_the_pixel_centre_convention():
    c = block_centres(16, 24)
    assert c.shape == (2 * 3, 2)
    assert np.allclose(c[0], [3.5, 3.5]) and np.allclose(c[-1], [19.5, 11.5])


def test_rigid_background_is_on_its_epipolar_lines_and_the_mover_is_not():
    flow, mover, _ = _scene()
    d = epipolar_distance(flow, np.ones((H // 8, W // 8)))
    assert d.shape == (H // 8, W // 8)
    cells = mover.reshape(H // 8, 8, W // 8, 8).all(axis=(1, 3))
    assert np.median(d[~cells]) < 0.05
    assert np.min(d[cells]) > 1.0


def test_low_confidence_pixels_do_not_fit_the_geometry():
    flow, mover, _ = _scene()
    weight = np.ones((H // 8, W // 8))
    weight[:2] = 0.0
    assert epipolar_distance(flow, weight) is not None
    assert epipolar_distance(flow, np.zeros((H // 8, W // 8))) is None


def test_moving_mask_takes_any_edge_and_grows_by_the_dilation():
    d1 = np.zeros((12, 16), np.float32)
    d2 = np.zeros((12, 16), np.float32)
    d1[5, 5] = 2.0
    d2[8, 10] = 2.0
    m = moving_mask([d1, d2], thresh=0.5, dilate=0)
    assert m.sum() == 2 and m[5, 5] and m[8, 10]
    grown = moving_mask([d1, d2], thresh=0.5, dilate=1)
    assert grown.sum() == 18 and grown[4, 4] and not grown[3, 5]


def test_moving_mask_grows_less_when_the_full_growth_covers_too_much():
    """A mover over a fifth of the view: grown by 2 cells it would cover more than half, so with a limit
    of 0.5 it is grown by the most cells that stay within it (1), and left ungrown when none does."""
    d = np.zeros((12, 16), np.float32)
    d[2:9, 3:10] = 2.0  # 49 of 192 cells
    full = moving_mask([d], thresh=0.5, dilate=2)
    assert full.sum() == 11 * 11
    one = moving_mask([d], thresh=0.5, dilate=2, limit=0.5)
    assert one.sum() == 9 * 9 and one[1, 2] and not one[0, 1]
    bare = moving_mask([d], thresh=0.5, dilate=2, limit=0.3)
    assert bare.sum() == 49
    assert np.array_equal(moving_mask([d], thresh=0.5, dilate=2, limit=0.7), full)


def test_moving_mask_threshold_rises_with_the_noise_level():
    noisy = np.full((12, 16), 0.4, np.float32)
    noisy[0, 0] = 0.4 * NOISE_FACTOR * 0.9  # above the fixed threshold, below the noise-scaled one
    noisy[1, 1] = 0.4 * NOISE_FACTOR * 1.1
    m = moving_mask([noisy], thresh=0.5, dilate=0)
    assert not m[0, 0] and m[1, 1] and m.sum() == 1


@pytest.mark.parametrize("dilate", [0, 2])
def test_epipolar_mask_finds_the_mover_end_to_end(dilate):
    flow, mover, _ = _scene()
    d = epipolar_distance(flow, np.ones((H // 8, W // 8)))
    m = moving_mask([d], thresh=0.5, dilate=dilate)
    cells = mover.reshape(H // 8, 8, W // 8, 8).all(axis=(1, 3))
    assert m[cells].all()
    assert m.mean() < 0.5


def test_a_mover_under_pure_rotation_is_found_by_the_homography_test():
    """Pure rotation: x_j = K R K⁻¹ x_i for every depth, F is degenerate (any epipole fits), so a mover
    walking along the fitted epipolar lines would pass; the homography transfer error flags it."""
    ys, xs = np.mgrid[0:H, 0:W].astype(np.float64)
    a = np.deg2rad(2.0)
    rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])  # a pan
    hom = K @ rot @ np.linalg.inv(K)
    p = hom @ np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)])
    flow = np.stack([p[0] / p[2] - xs.ravel(), p[1] / p[2] - ys.ravel()], 1).reshape(H, W, 2).astype(np.float32)
    mover = np.zeros((H, W), bool)
    mover[24:56, 32:64] = True
    flow[mover] += np.array([3.0, 0.0], np.float32)  # moves along the pan, the direction F cannot tell apart
    d = epipolar_distance(flow, np.ones((H // 8, W // 8)))
    cells = mover.reshape(H // 8, 8, W // 8, 8).all(axis=(1, 3))
    assert np.median(d[~cells]) < 0.05
    assert np.min(d[cells]) > 1.0


def test_the_fit_recovers_the_rigid_geometry_through_outliers_and_noise_and_repeats_itself():
    """RANSAC alone stops at its inlier band (0.3 px); the refits on the robust inliers bring the fit to the
    noise: the noise-free rigid points lie almost on the fitted F's epipolar lines, and the fit is deterministic."""
    from droidw_cli.dynamics.epipolar import fit_fundamental

    rng = np.random.default_rng(3)
    n = 600
    x_i = np.stack([rng.uniform(0, 511, n), rng.uniform(0, 383, n)], 1)
    depth = rng.uniform(2.0, 8.0, n)
    k = np.array([[400.0, 0, 255.5], [0, 400.0, 191.5], [0, 0, 1]])
    t = np.array([0.3, 0.05, 0.1])
    rays = np.linalg.inv(k) @ np.vstack([x_i.T, np.ones(n)])
    proj = k @ (rays * depth - t[:, None])
    x_j = (proj[:2] / proj[2]).T + rng.normal(0.0, 0.05, (n, 2))  # DIS-like noise on the block means
    outliers = rng.random(n) < 0.3
    x_j[outliers] += rng.normal(0.0, 8.0, (outliers.sum(), 2))  # movers: 30 % of the points
    f_true = np.linalg.inv(k).T @ _skew(t) @ np.linalg.inv(k)
    clean = x_j.copy()
    clean[~outliers] = (proj[:2] / proj[2]).T[~outliers]

    f = fit_fundamental(x_i, x_j, 0.3)
    assert f is not None and f.shape == (3, 3)
    assert np.array_equal(f, fit_fundamental(x_i, x_j, 0.3))
    rigid = ~outliers
    # the fitted F explains the rigid points to their noise, and their noise-free positions almost exactly
    assert np.median(sampson_distance(f, x_i[rigid], x_j[rigid])) < 0.06
    assert np.median(sampson_distance(f, x_i[rigid], clean[rigid])) < 0.03
    # ... and flags the movers
    assert np.median(sampson_distance(f, x_i[outliers], x_j[outliers])) > 1.0
    assert np.median(sampson_distance(f_true, x_i[rigid], clean[rigid])) < 1e-6  # the test's own geometry is right


def test_cells_an_edge_does_not_see_neither_count_nor_raise_its_threshold():
    """A cell whose correspondence leaves the view on one edge was not measured there: DIS extrapolates its
    flow, and its large distance must neither flag it nor raise the edge's noise threshold (the median)."""
    rng = np.random.default_rng(0)
    everywhere = np.ones((12, 16), bool)
    d_short = rng.uniform(0.0, 0.1, (12, 16)).astype(np.float32)  # the adjacent edge: everything in view
    for gone in (4, 10):  # columns that leave the view on the long edge
        d_long = rng.uniform(0.0, 0.1, (12, 16)).astype(np.float32)
        d_long[:, :gone] = 5.0  # extrapolated flow there, far off its epipolar line
        d_long[5, 12] = 2.0     # a mover inside the view
        seen_long = everywhere.copy()
        seen_long[:, :gone] = False
        blind = moving_mask([d_long, d_short], thresh=0.5, dilate=0)
        if gone == 4:
            assert blind[:, :gone].all()  # the old rule zeroes them on every edge
        else:
            assert not blind[5, 12]       # the old rule: their 5 px median hides the mover
        m = moving_mask([d_long, d_short], thresh=0.5, dilate=0, seen=[seen_long, everywhere])
        assert m[5, 12] and m.sum() == 1
    assert not moving_mask([d_long], thresh=0.5, dilate=0, seen=[~everywhere]).any()
