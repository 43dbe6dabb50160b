"""Keyframe management in DROID's grid units: frame distance, motion filter, proximity, removal, parallax gate."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from droidw_cli.config import MotionFilterConfig
from droidw_cli.slam import graph
from droidw_cli.slam.distance import frame_distance, transfer_disparity
from droidw_cli.slam.keyframes import GROW_MIN, KeyframeBuffer, grown_capacity
from droidw_cli.slam import motion_filter
from droidw_cli.slam.motion_filter import MotionFilter, grey_small, motion_evidence
from droidw_cli.slam.parallax import homography_parallax

K8 = torch.tensor([50.0, 50.0, 31.5, 23.5])  # 1/8-grid intrinsics of a 384×512 working image
GRID = (48, 64)


def _pose(t=(0.0, 0.0, 0.0), q=(0.0, 0.0, 0.0, 1.0)) -> torch.Tensor:
    return torch.tensor([*t, *q], dtype=torch.float32)


def test_frame_distance_of_a_sideways_translation_is_f_t_d():
    """A fronto-parallel plane at disparity d, camera moved sideways by t: every pixel moves f·t·d grid px."""
    d, t = 0.5, 0.2
    poses = torch.stack([_pose(), _pose((-t, 0.0, 0.0))])  # world-to-camera: camera centre at +t
    disps = torch.full((2, *GRID), d)
    dist = frame_distance(poses, disps, K8, torch.tensor([0]), torch.tensor([1]), beta=0.75)
    assert dist.item() == pytest.approx(50.0 * t * d, rel=1e-4)  # full and translation-only flows agree


def test_frame_distance_discounts_rotation():
    """A pure rotation: the translation-only term is zero, so d = β · (rotation flow)."""
    angle = 0.02
    q = (0.0, np.sin(angle / 2), 0.0, np.cos(angle / 2))
    poses = torch.stack([_pose(), _pose(q=q)])
    disps = torch.full((2, *GRID), 0.5)
    full = frame_distance(poses, disps, K8, torch.tensor([0]), torch.tensor([1]), beta=1.0).item()
    mixed = frame_distance(poses, disps, K8, torch.tensor([0]), torch.tensor([1]), beta=0.75).item()
    assert 50.0 * angle <= full <= 1.25 * 50.0 * angle  # f·ω at the centre, f(1 + x²)·ω off it
    assert mixed == pytest.approx(0.75 * full, rel=1e-4)


def test_transfer_disparity_of_a_forward_move_grows_the_disparity():
    """A plane at depth 2 seen after moving 0.5 forward is at depth 1.5: disparity 1/1.5."""
    poses = _pose(), _pose((0.0, 0.0, -0.5))
    out = transfer_disparity(poses[0], torch.full(GRID, 0.5), poses[1], K8)
    assert out.shape == GRID
    assert torch.allclose(out, torch.full(GRID, 1 / 1.5), rtol=1e-4)


def _textured(h=384, w=512, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 255, (h // 8, w // 8), dtype=np.uint8)
    grey = cv2.GaussianBlur(cv2.resize(small, (w + 64, h + 64), interpolation=cv2.INTER_CUBIC), (5, 5), 1.0)
    return np.repeat(grey[..., None], 3, axis=2)


def test_motion_filter_threshold_is_in_grid_pixels():
    """24 working px of shift = 3 grid px: a keyframe at thresh 3.0, none at 3.5."""
    big = _textured()
    a, b = big[:384, 32:544], big[:384, 8:520]  # image shifted by 24 px
    for thresh, expected in ((2.8, True), (3.5, False)):
        mf = MotionFilter(MotionFilterConfig(thresh=thresh, max_gap=100))
        mf.check(np.ascontiguousarray(a), False)
        mf.accept(np.ascontiguousarray(a))
        is_kf, stats = mf.check(np.ascontiguousarray(b), True)
        assert stats.mean == pytest.approx(3.0, abs=0.25)
        assert is_kf is expected


def test_the_accepted_flow_of_a_small_motion_is_kept_only_when_asked():
    """An 8 px shift (1 grid px; carried on, 2 < START_MIN): too small to start the next frame's flow, so by default the
    accepted candidate brings no flow; with ``keep_every_flow`` (rotation starts) it brings the one measured."""
    big = _textured()
    a, b = np.ascontiguousarray(big[:384, 32:544]), np.ascontiguousarray(big[:384, 24:536])
    for keep in (False, True):
        mf = MotionFilter(MotionFilterConfig(thresh=0.8, max_gap=100), keep_every_flow=keep)
        mf.check(a, True)
        mf.accept(a)
        assert mf.check(b, True)[0]
        mf.accept(b)
        if keep:
            assert mf.accepted_flow is not None and float(np.median(mf.accepted_flow[..., 0])) == pytest.approx(4.0, abs=0.3)
        else:
            assert mf.accepted_flow is None


def test_fixed_camera_makes_no_keyframe_before_initialisation():
    img = np.ascontiguousarray(_textured()[:384, :512])
    mf = MotionFilter(MotionFilterConfig())
    assert mf.check(img, False)[0]  # the first frame
    mf.accept(img)
    assert not any(mf.check(img.copy(), False)[0] for _ in range(20))  # no max_gap before initialisation


def test_near_still_camera_gets_keyframes_every_max_gap_before_initialisation():
    """Before initialisation a whole-image shift of 1 grid px (8 working px, under the 3-px median test)
    becomes a keyframe candidate once max_gap frames have passed; a mover filling 60 % of a fixed
    camera's view (its median moves, its lower quartile does not) never does."""
    big = _textured()
    ref = np.ascontiguousarray(big[:384, 32:544])
    shifted = np.ascontiguousarray(big[:384, 24:536])  # every pixel 8 px = 1 grid px
    mover = ref.copy()
    mover[:, :308] = big[:384, 24:332]  # the left 60 % moved by 8 px, the rest still
    for frame, expected in ((shifted, True), (mover, False)):
        mf = MotionFilter(MotionFilterConfig(max_gap=5))
        mf.check(ref, False)
        mf.accept(ref)
        decisions = [mf.check(frame.copy(), False)[0] for _ in range(6)]
        assert decisions == [False] * 4 + [expected] * 2
    off = MotionFilter(MotionFilterConfig(max_gap=5, init_min_quartile=0.0))
    off.check(ref, False)
    off.accept(ref)
    assert not any(off.check(shifted.copy(), False)[0] for _ in range(8))


def test_parallax_is_small_for_a_rotation_and_large_for_a_translation():
    """Rendered room: rotating the camera about its centre gives no parallax, moving it sideways does."""
    from droidw_cli.synth import SynthConfig, build_scene
    from droidw_cli.synth.paths import rot_y

    scene = build_scene(SynthConfig.preset("static-small", frames=2, seed=1))
    pose = scene.pose(0)
    rotated, moved = pose.copy(), pose.copy()
    rotated[:3, :3] = pose[:3, :3] @ rot_y(0.05)
    moved[:3, 3] += pose[:3, :3] @ np.array([0.3, 0.0, 0.0])
    first = scene.render(0)[0]
    # this view is mostly one wall 3.5-3.8 m away: little parallax even for 30 cm (measured 0.15 grid px)
    assert homography_parallax(first, scene.render(0, pose_c2w=rotated)[0]) < 0.08
    assert homography_parallax(first, scene.render(0, pose_c2w=moved)[0]) > 0.12


def test_proximity_selection_with_nms():
    cand = [(10, 2), (10, 3), (10, 6), (9, 2), (8, 5)]
    dist = torch.tensor([1.0, 2.0, 3.0, 4.0, 20.0])
    out = graph.select_proximity(cand, dist, thresh=16.0, nms=1, existing=set(), limit=3)
    # (10, 3) and (9, 2) are within 1 keyframe of (10, 2); (8, 5) is over the threshold
    assert out == [(2, 10), (10, 2), (6, 10), (10, 6)]
    # an existing edge suppresses its neighbourhood too
    out = graph.select_proximity(cand, dist, 16.0, 1, existing={(9, 3)}, limit=3)
    assert (2, 10) not in out and (6, 10) in out


def test_depth_prior_without_valid_pixels_fixes_no_scale():
    """A keyframe whose sensor depth is 0 (invalid) everywhere does not make the run metric; one valid pixel does."""
    buf = KeyframeBuffer((2, 3), capacity=2)
    thumb = np.zeros((1, 1, 3), np.uint8)
    buf.append(0, 0.0, _pose((0.0, 0, 0)), 1.0, thumb, depth_prior=torch.zeros(2, 3))
    assert not buf.has_prior and buf.depth_prior is not None
    prior = torch.zeros(2, 3)
    prior[1, 2] = 0.5
    buf.append(1, 1.0, _pose((1.0, 0, 0)), 1.0, thumb, depth_prior=prior)
    assert buf.has_prior and buf.depth_prior[1, 1, 2].item() == 0.5
    buf.append(2, 2.0, _pose((2.0, 0, 0)), 1.0, thumb, depth_prior=torch.zeros(2, 3))
    assert buf.has_prior


def test_keyframe_removal_renumbers_buffer_and_edges():
    buf = KeyframeBuffer((2, 3), capacity=2)
    for n in range(4):
        buf.append(10 * n, float(n), _pose((float(n), 0, 0)), float(n + 1), np.zeros((1, 1, 3), np.uint8))
    buf.remove(2)
    assert len(buf) == 3 and buf.frame_index == [0, 10, 30]
    assert buf.poses[2, 0].item() == 3.0 and buf.disps[2, 0, 0].item() == 4.0
    cache = graph.EdgeCache()
    for p in [(0, 1), (1, 2), (2, 3), (3, 1)]:
        cache.put(*p, torch.zeros(2, 3, 2), torch.ones(2, 3, 2), born=5)
    cache.remove_frame(2)
    assert sorted(cache.pairs()) == [(0, 1), (2, 1)]
    assert cache.young_pairs(now=50, max_age=50) == cache.pairs()
    assert cache.young_pairs(now=56, max_age=50) == []


def test_archived_keyframes_keep_u_and_confidence_but_not_features():
    buf = KeyframeBuffer((6, 8), feature_channels=4)
    for k in range(5):
        buf.append(k, k / 30.0, _pose(), 1.0, np.zeros((2, 2, 3), np.uint8), features=torch.full((4, 6, 8), float(k)))
    buf.archive(0, torch.full((6, 8), 0.25), torch.full((6, 8), 0.5))
    buf.archive(1, torch.full((6, 8), 0.75), torch.full((6, 8), 0.5))
    assert buf.features[0] is None and buf.features[1] is None
    with pytest.raises(ValueError, match="archived"):
        buf.feature_block(0, 3)
    assert torch.equal(buf.feature_block(2, 5)[:, 0, 0, 0], torch.tensor([2.0, 3.0, 4.0]))
    buf.remove(0)  # renumbers the frozen maps with the rest
    assert set(buf.frozen_u) == {0} and float(buf.frozen_u[0][0, 0]) == 0.75
    assert torch.equal(buf.feature_block(1, 4)[:, 0, 0, 0], torch.tensor([2.0, 3.0, 4.0]))


def test_monocular_buffer_keeps_no_prior_and_allocates_it_with_the_first_one():
    buf = KeyframeBuffer((6, 8), capacity=2)
    for k in range(3):
        buf.append(k, k / 30.0, _pose(), 1.0, np.zeros((2, 2, 3), np.uint8))
    assert buf.depth_prior is None and not buf.has_prior
    buf.append(3, 0.1, _pose(), 1.0, np.zeros((2, 2, 3), np.uint8), depth_prior=torch.full((6, 8), 0.5))
    buf.append(4, 0.2, _pose(), 1.0, np.zeros((2, 2, 3), np.uint8))
    assert buf.has_prior and buf.depth_prior.shape == buf.disps.shape
    assert buf.depth_prior[:3].abs().sum() == 0 and float(buf.depth_prior[3, 0, 0]) == 0.5
    buf.remove(0)
    assert float(buf.depth_prior[2, 0, 0]) == 0.5 and float(buf.depth_prior[3, 0, 0]) == 0.0


def test_pending_features_are_fetched_when_first_read():
    """A keyframe's features may be a future (extraction on a worker): read once, stored like the others."""
    from concurrent.futures import Future

    buf = KeyframeBuffer(GRID, feature_channels=4)
    ready, pending = torch.rand(4, *GRID), Future()
    buf.append(0, 0.0, _pose(), 1.0, np.zeros((6, 8, 3), np.uint8), ready)
    buf.append(1, 0.1, _pose(), 1.0, np.zeros((6, 8, 3), np.uint8), pending)
    later = torch.rand(4, *GRID)
    pending.set_result(later)
    block = buf.feature_block(0, 2)
    assert block.dtype == torch.float16
    assert torch.equal(block[1], later.half()) and torch.equal(block[0], ready.half())
    assert isinstance(buf.features[1], torch.Tensor)  # fetched once, then kept
    buf.remove(0)
    assert torch.equal(buf.feature_block(0, 1)[0], later.half())


def test_capacity_grows_by_a_quarter_and_keeps_every_value():
    """Growth copies the rows into a larger tensor (poses, disparities, prior) and fills the new ones."""
    assert grown_capacity(2) == 2 + GROW_MIN and grown_capacity(1024) == 1280
    buf = KeyframeBuffer((3, 4), capacity=2)
    n = 2 + GROW_MIN + 1  # two growth steps
    for k in range(n):
        prior = torch.full((3, 4), 0.5 + k) if k >= 1 else None
        buf.append(k, k / 30.0, _pose((float(k), 0, 0)), float(k + 1), np.zeros((2, 2, 3), np.uint8),
                   depth_prior=prior)
    assert len(buf) == n and buf.capacity == grown_capacity(grown_capacity(2))
    assert torch.equal(buf.poses[:n, 0], torch.arange(n, dtype=torch.float32))
    assert torch.equal(buf.disps[:n, 1, 2], torch.arange(1, n + 1, dtype=torch.float32))
    assert float(buf.depth_prior[0].abs().sum()) == 0.0
    assert torch.equal(buf.depth_prior[1:n, 0, 0], 0.5 + torch.arange(1, n, dtype=torch.float32))
    # the rows past the count hold the fill values: identity pose, disparity 1, no prior
    assert torch.equal(buf.poses[n:], torch.tensor([0, 0, 0, 0, 0, 0, 1.0]).expand(buf.capacity - n, 7))
    assert bool((buf.disps[n:] == 1.0).all()) and bool((buf.depth_prior[n:] == 0.0).all())


def _flat_wall_beside_a_mover(shift: int) -> np.ndarray:
    """A fixed camera: a flat grey wall (sensor noise only) and a textured mover over 45 % of the width that has
    moved ``shift`` px since the first frame (working size 384 × 512)."""
    rng = np.random.default_rng(shift)
    tex = cv2.GaussianBlur(np.random.default_rng(0).uniform(0, 255, (384, 512)).astype(np.float32), (0, 0), 2.0)
    img = np.full((384, 512), 128.0, np.float32) + rng.normal(0, 1.5, (384, 512))
    img[:, 40 + shift:270 + shift] = (tex[:, :230] - tex.mean()) * 4 + 128
    return cv2.cvtColor(np.clip(img, 0, 255).astype(np.uint8), cv2.COLOR_GRAY2RGB)


def test_motion_evidence_is_where_the_flow_explains_the_change():
    """Flow on a textured shift is evidenced; flow claimed on a flat wall or on a static texture is not."""
    grey = cv2.cvtColor(_textured()[:192, :256], cv2.COLOR_RGB2GRAY)
    moved = np.ascontiguousarray(np.roll(grey, 4, axis=1))
    flow = np.zeros((192, 256, 2), np.float32)
    flow[..., 0] = 4.0
    assert motion_evidence(grey, moved, flow)[:, 16:-16].mean() > 0.95  # the true flow of a shifted texture
    assert not motion_evidence(grey, grey, flow).any()  # a static texture given a wrong flow
    flat = np.full((192, 256), 128, np.uint8)
    noisy = np.clip(128 + np.random.default_rng(1).normal(0, 1.5, flat.shape), 0, 255).astype(np.uint8)
    assert not motion_evidence(flat, noisy, flow).any()  # a flat wall: no flow is told from another


def test_a_flat_wall_that_the_flow_drags_along_with_a_mover_makes_no_keyframe():
    """DIS drags the mover's motion over the flat wall beside it: its lower quartile passes 0.5 grid px, but the
    images confirm the motion on too few pixels (motion_filter.EVIDENCE_MIN)."""
    ref, later = _flat_wall_beside_a_mover(0), _flat_wall_beside_a_mover(8)
    assert MotionFilter(MotionFilterConfig()).flow_stats(grey_small(ref), grey_small(later), quartile=True).quartile > 0.5
    for floor, expected in ((motion_filter.EVIDENCE_MIN, False), (0.0, True)):
        mf = MotionFilter(MotionFilterConfig(max_gap=5))
        mf.check(ref, False)
        mf.accept(ref)
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(motion_filter, "EVIDENCE_MIN", floor)
            assert [mf.check(later.copy(), False)[0] for _ in range(6)] == [False] * 4 + [expected] * 2


def test_auto_calibration_keeps_the_shorter_keyframe_gap():
    """With --calib auto the focal length is estimated from the keyframes' views: the motion filter forces a
    keyframe every ``max_gap_auto`` frames at most (on a 70-frame clip f read 0.2 % off at 9, 10.6 % at 13,
    tests/test_track_pipeline.py); a known calibration takes ``max_gap``; a smaller ``max_gap`` stays."""
    import dataclasses

    from droidw_cli.config import TrackConfig
    from droidw_cli.slam.tracker import motion_filter_config

    cfg = TrackConfig()
    assert cfg.motion_filter.max_gap == 13 and cfg.motion_filter.max_gap_auto == 9
    assert motion_filter_config(cfg, auto=False).max_gap == 13
    assert motion_filter_config(cfg, auto=True).max_gap == 9
    small = dataclasses.replace(cfg, motion_filter=dataclasses.replace(cfg.motion_filter, max_gap=5))
    assert motion_filter_config(small, auto=True).max_gap == 5
    with pytest.raises(ValueError):
        dataclasses.replace(cfg.motion_filter, max_gap_auto=0)
