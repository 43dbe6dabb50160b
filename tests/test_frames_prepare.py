"""FramePreparer: working size, intrinsics after resize/crop, depth, undistortion."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from droidw_cli.io.calibration import Calibration
from droidw_cli.io.frames import Frame
from droidw_cli.io.prepare import FramePreparer, preparer_for


def render_dots(h: int, w: int, centres: np.ndarray, sigma: float) -> np.ndarray:
    """uint8 RGB image with Gaussian dots at sub-pixel ``centres`` (N, 2) = (u, v), pixel-centre convention."""
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    d2 = (u[None] - centres[:, 0, None, None]) ** 2 + (v[None] - centres[:, 1, None, None]) ** 2
    img = 20 + 220 * np.exp(-d2 / (2 * sigma**2)).sum(0)
    return np.repeat(np.clip(np.round(img), 0, 255).astype(np.uint8)[..., None], 3, axis=2)


def dot_centroids(img: np.ndarray, guesses: np.ndarray, radius: int) -> np.ndarray:
    """Intensity-weighted centroids (background removed) in windows around ``guesses``."""
    grey = img[..., 0].astype(np.float64) - 20.0
    out = []
    for gu, gv in guesses:  # one window per dot, a handful of dots
        u0, v0 = int(round(gu)), int(round(gv))
        win = np.clip(grey[v0 - radius : v0 + radius + 1, u0 - radius : u0 + radius + 1], 0, None)
        vv, uu = np.mgrid[v0 - radius : v0 + radius + 1, u0 - radius : u0 + radius + 1]
        out.append([(win * uu).sum() / win.sum(), (win * vv).sum() / win.sum()])
    return np.array(out)


def project(k, pts: np.ndarray) -> np.ndarray:
    fx, fy, cx, cy = k
    return np.stack([fx * pts[:, 0] / pts[:, 2] + cx, fy * pts[:, 1] / pts[:, 2] + cy], axis=1)


@pytest.mark.parametrize("hw", [(480, 854), (576, 768), (540, 960), (37, 100), (384, 512)])
def test_working_size_is_multiple_of_8(hw):
    prep = FramePreparer(hw, None)
    h, w = prep.size
    assert h % 8 == 0 and w % 8 == 0 and prep.intrinsics is None
    assert abs(h * w - 384 * 512) < 0.08 * 384 * 512
    img = np.zeros(hw + (3,), np.uint8)
    out, depth = prep(img)
    assert out.shape == (h, w, 3) and out.dtype == np.uint8 and depth is None and out.flags.c_contiguous


@pytest.mark.parametrize("hw,area", [((540, 960), 384 * 512), ((150, 200), 384 * 512), ((300, 412), 96 * 128)])
def test_rescaled_intrinsics_project_like_the_image(hw, area):
    """A 3D point's projection with the new intrinsics lands on its dot in the prepared image."""
    h, w = hw
    k = np.array([0.8 * w, 0.82 * w, w / 2 - 3.3, h / 2 + 2.1])
    rng = np.random.default_rng(0)
    uu, vv = np.meshgrid([0.2 * w, 0.5 * w, 0.8 * w], [0.25 * h, 0.75 * h])
    pix = np.column_stack([uu.ravel(), vv.ravel()]) + rng.uniform(-0.5, 0.5, (6, 2))  # well-separated dots
    z = rng.uniform(1.0, 3.0, 6)
    pts = np.column_stack([(pix[:, 0] - k[2]) / k[0] * z, (pix[:, 1] - k[3]) / k[1] * z, z])
    img = render_dots(h, w, project(k, pts), sigma=0.012 * w)
    prep = FramePreparer(hw, tuple(k), target_area=area)
    out = prep.image(img)
    expected = project(prep.intrinsics, pts)
    radius = max(4, int(4 * 0.012 * w * prep.size[1] / w))
    got = dot_centroids(out, expected, radius)
    assert np.abs(got - expected).max() < 0.05  # measured error is under 0.02 px
    # the naive scaling c' = c·s (no half-pixel terms, no crop offset) would be visibly wrong
    naive = project(k * np.array([prep.size[1] / w, prep.size[0] / h] * 2), pts)
    assert np.abs(got - naive).max() > 0.15


def test_calibration_prepared_matches_preparer():
    calib = Calibration(500.0, 505.0, 479.5, 269.5)
    prep = FramePreparer((540, 960), calib)
    assert prep.calibration.as_array() == pytest.approx(calib.prepared((540, 960)).as_array())
    assert prep.calibration.as_array() == pytest.approx(calib.scaled((540, 960), prep.resized_size, prep.size).as_array())


def test_depth_nearest_keeps_values_and_invalid():
    rng = np.random.default_rng(1)
    depth = rng.choice(np.array([0.0, 1.5, 2.25, 4.0], np.float32), size=(240, 320))
    prep = FramePreparer((240, 320), None, target_area=120 * 160)
    _, out = prep(np.zeros((240, 320, 3), np.uint8), depth)
    assert out.shape == prep.size and out.dtype == np.float32
    assert set(np.unique(out)) <= {0.0, 1.5, 2.25, 4.0} and (out == 0).any()
    # exact 2× downsample: nearest of pixel centre (2y + ½) is one of the block's pixels
    block = depth.reshape(120, 2, 160, 2)
    assert np.all((out[..., None, None] == block.transpose(0, 2, 1, 3).reshape(120, 160, 2, 2)).any(axis=(2, 3)))


def test_frame_keeps_index_timestamp_and_checks_size():
    prep = FramePreparer((96, 128), (100, 100, 63.5, 47.5), target_area=48 * 64)
    f = Frame(7, 1.25, np.zeros((96, 128, 3), np.uint8), np.ones((96, 128), np.float32))
    g = prep.frame(f)
    assert (g.index, g.timestamp) == (7, 1.25) and g.image.shape == (48, 64, 3) and g.depth.shape == (48, 64)
    with pytest.raises(ValueError, match="preparer was made for"):
        prep.image(np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(ValueError, match="needs the intrinsics"):
        FramePreparer((96, 128), None, distortion=(0.1, 0, 0, 0))


def test_enlarging_uses_linear_and_identity_is_exact():
    img = (np.random.default_rng(2).random((64, 96, 3)) * 255).astype(np.uint8)
    same = FramePreparer((64, 96), None, target_area=64 * 96)
    assert same.size == (64, 96) and np.array_equal(same.image(img), img)
    big = FramePreparer((64, 96), None, target_area=4 * 64 * 96)
    assert big.size == (128, 192)
    assert np.array_equal(big.image(img), cv2.resize(img, (192, 128), interpolation=cv2.INTER_LINEAR))


def test_undistorts_a_distorted_grid():
    h, w = 240, 320
    k = np.array([250.0, 250.0, 159.5, 119.5])
    dist = (-0.25, 0.05, 0.001, -0.001)
    uu, vv = np.meshgrid(np.arange(40, 290, 40.0), np.arange(30, 220, 45.0))
    ideal = np.column_stack([uu.ravel(), vv.ravel()])
    rays = np.column_stack([(ideal[:, 0] - k[2]) / k[0], (ideal[:, 1] - k[3]) / k[1], np.ones(len(ideal))])
    kmat = np.array([[k[0], 0, k[2]], [0, k[1], k[3]], [0, 0, 1]])
    distorted, _ = cv2.projectPoints(rays, np.zeros(3), np.zeros(3), kmat, np.array(dist))
    distorted = distorted.reshape(-1, 2)
    img = render_dots(h, w, distorted, sigma=1.5)
    assert np.abs(distorted - ideal).max() > 4  # the distortion is substantial
    prep = FramePreparer((h, w), Calibration(*k, distortion=dist), target_area=h * w)
    assert prep.size == (h, w) and prep.calibration.distortion == ()
    got = dot_centroids(prep.image(img), ideal, radius=5)
    assert np.abs(got - ideal).max() < 0.35
    plain = FramePreparer((h, w), tuple(k), target_area=h * w)  # no undistortion: dots stay displaced
    assert np.abs(dot_centroids(plain.image(img), distorted, radius=5) - ideal).max() > 4


def test_preparer_for_uses_hint():
    class Src:
        size = (96, 128)
        intrinsics_hint = Calibration(100.0, 100.0, 63.5, 47.5)

    prep = preparer_for(Src(), target_area=48 * 64)
    assert prep.intrinsics == pytest.approx([50.0, 50.0, 31.5, 23.5])
    assert preparer_for(Src(), Calibration(10.0, 10.0, 0.0, 0.0), 48 * 64).intrinsics[0] == pytest.approx(5.0)
