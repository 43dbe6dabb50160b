"""DIS correspondences on synthetic pairs with known motion: targets, confidence, init flow."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from droidw_cli.config import CorrespondenceConfig
from droidw_cli.correspondence import Correspondence, DISCorrespondence, grid_coordinates
from droidw_cli.correspondence.dis import to_gray
from droidw_cli.errors import ConfigError

H, W = 256, 320


def texture(h: int, w: int, seed: int) -> np.ndarray:
    """Smooth random RGB texture: blurred noise at several scales, uint8."""
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w, 3), np.float32)
    for sigma, amp in [(1.5, 0.4), (4.0, 1.0), (10.0, 1.0), (25.0, 0.7)]:
        n = cv2.GaussianBlur(rng.standard_normal((h, w, 3)).astype(np.float32), (0, 0), sigma)
        img += amp * n / n.std()
    img = (img - img.min()) / (img.max() - img.min())
    return (img * 255).round().astype(np.uint8)


def warp(img: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Image j with j(M x) = i(x): pixel x of i moves to M x."""
    h, w = img.shape[:2]
    return cv2.warpAffine(img, m, (w, h), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)


def expected_target(m: np.ndarray, h: int, w: int) -> np.ndarray:
    """Grid targets of an affine motion: the block mean of an affine flow is its value at the block centre 8g + 3.5."""
    centre = 8 * grid_coordinates(h // 8, w // 8) + 3.5
    return (centre @ m[:, :2].T + m[:, 2] - 3.5) / 8


@pytest.fixture(scope="module")
def image() -> np.ndarray:
    return texture(H, W, 0)


MOTIONS = {
    "subpixel_translation": np.float32([[1, 0, 5.3], [0, 1, -2.7]]),
    "zoom_rotation": cv2.getRotationMatrix2D((W / 2, H / 2), 3.0, 1.08).astype(np.float32),
}


@pytest.mark.parametrize("preset", ["fast", "fine", "medium"])
@pytest.mark.parametrize("motion", list(MOTIONS))
def test_targets_match_known_affine_motion(image, preset, motion):
    m = MOTIONS[motion]
    corr = DISCorrespondence(CorrespondenceConfig(preset=preset)).match(image, warp(image, m))
    assert isinstance(corr, Correspondence)
    assert corr.flow.shape == (H, W, 2) and corr.flow.dtype == np.float32
    assert corr.target.shape == (H // 8, W // 8, 2) and corr.target.dtype == torch.float32
    assert corr.weight.shape == (H // 8, W // 8, 2) and corr.weight.dtype == torch.float32
    err_px = 8 * np.linalg.norm(corr.target.numpy() - expected_target(m, H, W), axis=-1)[3:-3, 3:-3]
    assert np.median(err_px) < 0.5
    weight = corr.weight.numpy()
    assert np.array_equal(weight[..., 0], weight[..., 1])
    assert weight.min() >= 0.0 and weight.max() <= 1.0
    assert weight[3:-3, 3:-3].mean() > 0.8


def test_integer_shift_of_8px_gives_grid_plus_one(image):
    m = np.float32([[1, 0, 8], [0, 1, 0]])
    corr = DISCorrespondence().match(image, warp(image, m))
    t = corr.target.numpy()[2:-2, 2:-3]
    g = grid_coordinates(H // 8, W // 8)[2:-2, 2:-3]
    assert np.allclose(t[..., 0], g[..., 0] + 1, atol=0.02)
    assert np.allclose(t[..., 1], g[..., 1], atol=0.02)


def test_pasted_occluder_gets_low_weight(image):
    img_j = warp(image, np.float32([[1, 0, 3.0], [0, 1, 1.0]]))
    img_j[96:176, 120:216] = texture(H, W, 5)[96:176, 120:216]
    w = DISCorrespondence().match(image, img_j).weight[..., 0].numpy()
    inside = w[96 // 8 + 1 : 176 // 8 - 1, 120 // 8 + 1 : 216 // 8 - 1]
    outside = np.ones_like(w, bool)
    outside[96 // 8 - 2 : 176 // 8 + 2, 120 // 8 - 2 : 216 // 8 + 2] = False
    outside[:2] = outside[-2:] = False
    outside[:, :2] = outside[:, -2:] = False
    assert inside.mean() < 0.2
    assert w[outside].mean() > 0.9


def test_out_of_image_targets_have_zero_weight(image):
    m = np.float32([[1, 0, 24], [0, 1, 0]])  # the right 24 px of frame i leave frame j
    corr = DISCorrespondence().match(image, warp(image, m))
    w = corr.weight[..., 0].numpy()
    assert np.all(w[:, -3:] == 0.0)
    assert w[2:-2, 2:-5].mean() > 0.8


def test_a_flow_does_not_depend_on_the_calls_before_it():
    """OpenCV's DIS keeps a leftover of an initial flow for the next call without one: not visible here."""
    gray_i = cv2.cvtColor(texture(H, W, 5), cv2.COLOR_RGB2GRAY)
    gray_j = warp(gray_i, np.float32([[1, 0, 6.5], [0, 1, -3.0]]))
    fresh = DISCorrespondence().flow(gray_i, gray_j)
    dis = DISCorrespondence()
    dis.flow(gray_i, gray_j, np.full((H, W, 2), 5.0, np.float32))
    assert np.array_equal(fresh, dis.flow(gray_i, gray_j))


def test_init_flow_recovers_a_large_shift():
    h, w, dx, dy = 384, 512, 100, 5
    big = texture(h + 200, w + 200, 2)
    img_i = big[100 : 100 + h, 100 : 100 + w]
    img_j = big[100 - dy : 100 - dy + h, 100 - dx : 100 - dx + w]  # content moves by (+dx, +dy)
    expected = grid_coordinates(h // 8, w // 8) + np.float32([dx / 8, dy / 8])
    valid = expected[..., 0] < w // 8 - 1
    dis = DISCorrespondence()
    init = np.broadcast_to(np.float32([dx - 4, dy + 3]), (h, w, 2))  # a rough prior, off by 5 px
    plain, started = dis.match(img_i, img_j), dis.match(img_i, img_j, init_flow=init)
    err_plain = 8 * np.median(np.linalg.norm(plain.target.numpy() - expected, axis=-1)[valid])
    err_started = 8 * np.median(np.linalg.norm(started.target.numpy() - expected, axis=-1)[valid])
    assert err_started < 0.5
    assert err_plain > 10 * err_started
    assert started.weight[..., 0].numpy()[valid].mean() > 0.8
    assert started.weight[..., 0].numpy()[~valid].mean() < 0.1


def test_deterministic(image):
    img_j = warp(image, MOTIONS["zoom_rotation"])
    dis = DISCorrespondence()
    a, b = dis.match(image, img_j), DISCorrespondence().match(image, img_j)
    assert np.array_equal(a.flow, b.flow)
    assert torch.equal(a.target, b.target) and torch.equal(a.weight, b.weight)


def test_mean_flow_estimates_the_motion(image):
    dis = DISCorrespondence()
    m = np.float32([[1, 0, 6.0], [0, 1, -4.0]])
    assert dis.mean_flow(image, image) < 0.3
    assert abs(dis.mean_flow(image, warp(image, m)) - np.hypot(6, 4)) < 1.0


def test_match_many_stacks_edges(image):
    dis = DISCorrespondence(CorrespondenceConfig(preset="fast"))
    img_j = warp(image, MOTIONS["subpixel_translation"])
    targets, weights = dis.match_many([(image, img_j), (img_j, image)], init_flows=[None, None])
    assert targets.shape == (2, H // 8, W // 8, 2) and weights.shape == (2, H // 8, W // 8, 2)
    single = dis.match(img_j, image)
    assert torch.equal(targets[1], single.target) and torch.equal(weights[1], single.weight)
    # forward and backward targets roughly undo each other: mean flows are opposite
    fwd = (targets[0] - torch.from_numpy(grid_coordinates(H // 8, W // 8)))[3:-3, 3:-3].mean((0, 1))
    bwd = (targets[1] - torch.from_numpy(grid_coordinates(H // 8, W // 8)))[3:-3, 3:-3].mean((0, 1))
    assert torch.allclose(fwd, -bwd, atol=0.02)


def test_bad_inputs_are_rejected(image):
    dis = DISCorrespondence()
    with pytest.raises(ValueError, match="multiples of 8"):
        dis.match(image[:250], image[:250])
    with pytest.raises(ValueError, match="uint8"):
        dis.match(image.astype(np.float32), image.astype(np.float32))
    with pytest.raises(ValueError, match="differ in shape"):
        dis.match(image, image[:248])
    with pytest.raises(ValueError, match="init_flow must have shape"):
        dis.match(image, image, init_flow=np.zeros((H, W), np.float32))
    with pytest.raises(ValueError, match="at least one pair"):
        dis.match_many([])


@pytest.mark.parametrize("field, value", [("preset", "slow"), ("quick_preset", "slow"), ("fb_thresh", 0.0), ("photo_sigma", -1.0),
                                          ("smoothness", -1.0)])
def test_bad_config_is_a_config_error(field, value):
    with pytest.raises(ConfigError, match=field):
        DISCorrespondence(CorrespondenceConfig(**{field: value}))


def test_fine_preset_is_fast_with_a_finer_pyramid_and_the_filler_uses_it_by_default():
    from droidw_cli.correspondence.dis import create_dis

    fine, fast = create_dis("fine"), create_dis("fast")
    assert fine.getFinestScale() == 1 and fast.getFinestScale() == 2
    assert fine.getPatchSize() == fast.getPatchSize() and fine.getPatchStride() == 6
    assert fine.getVariationalRefinementIterations() == 0 < fast.getVariationalRefinementIterations()
    assert CorrespondenceConfig().quick_preset == "fine"


def test_match_all_on_threads_equals_one_after_the_other():
    """match_all spreads its calls over threads (per-thread DIS objects); results and order are unchanged."""
    from droidw_cli.correspondence.base import MatchCall

    img_i = texture(H, W, 7)
    shifts = [(3.0, 1.0), (-5.0, 2.5), (8.0, -4.0), (1.5, 6.0)]
    imgs = [warp(img_i, np.float32([[1, 0, dx], [0, 1, dy]])) for dx, dy in shifts]
    init = np.full((H, W, 2), 2.0, np.float32)
    calls = [MatchCall(img_i, im, init if k % 2 else None, both=k < 2) for k, im in enumerate(imgs)]
    derive = lambda c: float(c.weight.sum())  # noqa: E731
    seq = DISCorrespondence()
    seq.concurrent_match = False
    expected = seq.match_all(calls, derive)
    par = DISCorrespondence()
    got = par.match_all(calls, derive)
    assert [len(r) for r in got] == [2, 2, 1, 1]
    for a, b in zip(expected, got):
        for (ca, da), (cb, db) in zip(a, b):
            assert np.array_equal(ca.flow, cb.flow) and torch.equal(ca.weight, cb.weight) and da == db
    with pytest.raises(ValueError):
        par.match_all([calls[0], MatchCall(img_i, img_i[:, :W - 8])])


def test_staged_jobs_give_what_match_and_match_pair_give():
    """match_all runs each call as two flow jobs and one scoring job per correspondence: same results."""
    from droidw_cli.correspondence.base import MatchCall

    img_i = texture(H, W, 11)
    img_j = warp(img_i, np.float32([[1, 0, 4.0], [0, 1, -2.0]]))
    init = np.full((H, W, 2), 3.0, np.float32)
    dis = DISCorrespondence()
    pair, single = dis.match_all([MatchCall(img_i, img_j, init, both=True), MatchCall(img_j, img_i)])
    ref_pair = dis.match_pair(img_i, img_j, init)
    ref_single = dis.match(img_j, img_i)
    for (c, derived), ref in zip(pair + single, list(ref_pair) + [ref_single]):
        assert derived is None
        assert np.array_equal(c.flow, ref.flow) and torch.equal(c.target, ref.target) and torch.equal(c.weight, ref.weight)


def test_an_error_in_a_worker_job_reaches_the_caller():
    """A job that fails on any thread raises from match_all after the other jobs have stopped."""
    from droidw_cli.correspondence.base import MatchCall

    img = texture(H, W, 3)
    calls = [MatchCall(img, warp(img, np.float32([[1, 0, k], [0, 1, 0]]))) for k in range(4)]
    def derive(c):
        if c.mean_flow > 2.5:  # the 3 px shift only
            raise RuntimeError("derive failed")
        return 0

    with pytest.raises(RuntimeError, match="derive failed"):
        DISCorrespondence().match_all(calls, derive)


def test_smoothness_sets_the_edges_dis_alpha_and_leaves_the_fillers_flow_alone(image):
    """correspondence.smoothness replaces MEDIUM's variational α (20) for the edges' flow only."""
    from droidw_cli.correspondence.dis import create_dis

    assert create_dis("medium").getVariationalRefinementAlpha() == pytest.approx(20.0)
    assert create_dis("medium", 2.0).getVariationalRefinementAlpha() == pytest.approx(2.0)
    dis = DISCorrespondence(CorrespondenceConfig(preset="medium", quick_preset="medium", smoothness=2.0))
    shifted = np.roll(image, (3, 5), axis=(0, 1))
    dis.match(image, shifted)
    dis.quick_target(image, shifted)
    alphas = {key: obj.getVariationalRefinementAlpha() for key, obj in dis._local.dis.items()}
    assert alphas == {("medium", False, 2.0, None): pytest.approx(2.0), ("medium", False, 0.0, None): pytest.approx(20.0)}
    sharp = dis.flow(to_gray(image), to_gray(shifted))
    smooth = DISCorrespondence(CorrespondenceConfig(preset="medium")).flow(to_gray(image), to_gray(shifted))
    assert not np.array_equal(sharp, smooth)  # the setting reaches the flow
