"""DIS's coarsest pyramid level: the size rule, the padding that deepens it, and large shifts it then finds."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from droidw_cli.config import CorrespondenceConfig
from droidw_cli.correspondence import DISCorrespondence, grid_coordinates
from droidw_cli.correspondence.dis import calc_deep, calc_warped, create_dis, dis_levels, dis_objects, padded_size
from droidw_cli.errors import ConfigError

SHIFT = 44  # px: found from DIS MEDIUM's level 4, lost from its level 3 (on these textures)


def shifted_pair(h: int, w: int, dx: int = SHIFT, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Two gray crops of a random texture (Gaussian noise blurred by σ = 3 and 8 px, uint8), the content
    of the second moved by +dx px in x."""
    rng = np.random.default_rng(seed)
    img = np.zeros((h + 40, w + dx + 40), np.float32)
    for sigma in (3.0, 8.0):
        noise = cv2.GaussianBlur(rng.standard_normal(img.shape).astype(np.float32), (0, 0), sigma)
        img += noise / noise.std()
    img = ((img - img.min()) / (img.max() - img.min()) * 255).astype(np.uint8)
    return (np.ascontiguousarray(img[20:20 + h, dx + 20:dx + 20 + w]),
            np.ascontiguousarray(img[20:20 + h, 20:20 + w]))


def shift_error(flow: np.ndarray, dx: int = SHIFT) -> float:
    """Median |flow − (dx, 0)| px away from the borders (where the content leaves the image)."""
    inner = flow[16:-16, 16 + dx:-16]
    return float(np.median(np.linalg.norm(inner - np.float32([dx, 0]), axis=-1)))


def test_the_level_rule_predicts_where_dis_loses_a_44px_shift():
    """At 272 × 362 MEDIUM stops at level 3 and misses a 44 px shift; at 272 × 363 it reaches level 4 and finds it."""
    assert (dis_levels(272, 362, 8), dis_levels(272, 363, 8)) == (3, 4)
    assert dis_levels(384, 512, 8) == 4 and dis_levels(272, 360, 8) == 3
    for seed in range(3):
        errors = {w: shift_error(create_dis("medium").calc(*shifted_pair(272, w, seed=seed), None)) for w in (362, 363)}
        assert errors[362] > 20 and errors[363] < 0.5


@pytest.mark.parametrize("h, w, level", [(272, 360, 4), (272, 360, 5), (384, 512, 5), (120, 160, 4), (100, 100, 3),
                                         (512, 384, 5), (30, 40, 2)])
def test_padded_size_is_the_smallest_that_reaches_the_level(h, w, level):
    big_h, big_w = padded_size(h, w, 8, level)
    assert big_h >= h and big_w >= w
    assert dis_levels(big_h, big_w, 8) >= level
    side = 8 * 2 ** level
    if big_h > max(h, side):
        assert dis_levels(big_h - 1, big_w, 8) < level
    if big_w > max(w, side):
        assert dis_levels(big_h, big_w - 1, 8) < level


def test_padded_size_leaves_a_deep_enough_image_alone():
    assert padded_size(384, 512, 8, 4) == (384, 512)
    assert padded_size(272, 360, 8, 3) == (272, 360)


def test_calc_deep_finds_the_shift_that_dis_alone_misses():
    gray_i, gray_j = shifted_pair(272, 360)
    plain = calc_deep(dis_objects("medium"), gray_i, gray_j, None, 0)
    deep = calc_deep(dis_objects("medium"), gray_i, gray_j, None, 4)
    assert deep.shape == (272, 360, 2) and deep.dtype == np.float32
    assert shift_error(plain) > 20
    assert shift_error(deep) < 0.5


def test_each_level_more_finds_a_larger_shift():
    """56 px: lost from level 4, found from level 5 (1/32)."""
    gray_i, gray_j = shifted_pair(272, 360, dx=56)
    errors = [shift_error(calc_deep(dis_objects("medium"), gray_i, gray_j, None, level), dx=56) for level in (4, 5)]
    assert errors[0] > 20 and errors[1] < 0.5


def test_calc_deep_is_dis_itself_when_deep_enough_and_warps_by_a_start():
    gray_i, gray_j = shifted_pair(272, 360, dx=6)
    assert np.array_equal(calc_deep(dis_objects("medium"), gray_i, gray_j, None, 3),
                          create_dis("medium").calc(gray_i, gray_j, None))
    small = np.full((272, 360, 2), 5.0, np.float32)  # mean |f₀| under WARP_MIN of the diagonal: DIS's initial flow
    assert np.array_equal(calc_deep(dis_objects("medium"), gray_i, gray_j, small.copy(), 5),
                          dis_objects("medium")("seeded").calc(gray_i, gray_j, small.copy()))
    gray_i, gray_j = shifted_pair(272, 360, dx=14)
    start = np.full((272, 360, 2), 12.0, np.float32)  # over it: warped out
    started = calc_deep(dis_objects("medium"), gray_i, gray_j, start.copy(), 5)
    assert np.array_equal(started, calc_warped(dis_objects("medium"), gray_i, gray_j, start, 5))
    assert shift_error(started, dx=14) < 0.2


def zoomed_pair(h: int, w: int, zoom: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A texture and the same texture magnified by ``zoom`` about the image centre (a camera moving towards a
    wall), and the true flow from the first to the second."""
    big_i, _ = shifted_pair(h, w, dx=0, seed=1)
    centre = np.float32([(w - 1) / 2, (h - 1) / 2])
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    src = np.stack([xs, ys], -1)
    flow = (src - centre) * np.float32(zoom - 1)  # x → c + zoom (x − c)
    inv = centre + (src - centre) / np.float32(zoom)  # the second image samples the first at c + (x − c) / zoom
    gray_j = cv2.remap(big_i, inv[..., 0], inv[..., 1], cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    return big_i, gray_j, flow


def test_a_start_is_kept_under_a_strong_expansion():
    """A 30 % zoom (up to 50 px at the borders): DIS handed the exact flow as its initial flow searches again at
    every level and loses much of it; warped by the start, it only has to confirm it."""
    gray_i, gray_j, truth = zoomed_pair(272, 360, 1.3)
    inner = (slice(40, -40), slice(50, -50))

    def error(flow):
        return float(np.median(np.linalg.norm(flow[inner] - truth[inner], axis=-1)))

    seeded = create_dis("medium").calc(gray_i, gray_j, truth.copy())
    warped = calc_deep(dis_objects("medium"), gray_i, gray_j, truth.copy(), 0)
    assert error(warped) < 0.3 and error(warped) < 0.5 * error(seeded)


def test_the_source_uses_the_deeper_pyramid_for_edges_filler_and_mean_flow():
    h, w = 272, 360
    gray_i, gray_j = shifted_pair(h, w)
    img_i, img_j = (np.repeat(g[..., None], 3, axis=2) for g in (gray_i, gray_j))
    expected = grid_coordinates(h // 8, w // 8) + np.float32([SHIFT / 8, 0])
    inner = (slice(2, -2), slice(2 + SHIFT // 8, -2))
    for level, good in ((0, False), (4, True)):
        dis = DISCorrespondence(CorrespondenceConfig(coarsest_scale=level))
        edge = dis.match(img_i, img_j).target.numpy()
        quick = dis.quick_target(img_i, img_j).numpy()
        for target in (edge, quick):
            err = 8 * np.median(np.linalg.norm(target[inner] - expected[inner], axis=-1))
            assert (err < 1.0) == good, (level, err)
    # the source's mean flow (FAST at half size, so the level relative to the working size less one; FAST's
    # fewer iterations reach less far than MEDIUM from the same level)
    means = [DISCorrespondence(CorrespondenceConfig(coarsest_scale=level)).mean_flow(img_i, img_j) for level in (0, 5)]
    assert means[0] < 0.5 * SHIFT and abs(means[1] - SHIFT) < 2.0


def test_the_motion_filter_uses_the_deeper_pyramid_too():
    from droidw_cli.config import MotionFilterConfig
    from droidw_cli.slam.motion_filter import MotionFilter, grey_small

    img_i, img_j = (np.repeat(g[..., None], 3, axis=2) for g in shifted_pair(272, 360))
    small = grey_small(img_i), grey_small(img_j)
    means = [8 * MotionFilter(MotionFilterConfig(), level).flow_stats(*small).mean for level in (0, 5)]  # working px
    source = DISCorrespondence(CorrespondenceConfig(coarsest_scale=5)).mean_flow(img_i, img_j)
    assert means[0] < 0.5 * SHIFT and abs(means[1] - SHIFT) < 2.0
    assert means[1] == pytest.approx(source, rel=1e-5)  # the same half-size FAST flow as the source's


def test_deep_flows_are_deterministic():
    gray_i, gray_j = shifted_pair(272, 360)
    a = DISCorrespondence(CorrespondenceConfig(coarsest_scale=4)).flow(gray_i, gray_j)
    b = DISCorrespondence(CorrespondenceConfig(coarsest_scale=4)).flow(gray_i, gray_j)
    assert np.array_equal(a, b)


@pytest.mark.parametrize("value", [-1, 9])
def test_a_coarsest_scale_out_of_range_is_a_config_error(value):
    with pytest.raises(ConfigError, match="coarsest_scale"):
        DISCorrespondence(CorrespondenceConfig(coarsest_scale=value))
