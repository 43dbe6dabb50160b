"""The online trajectory filler: two-sided motion-only BA, relative-pose chain, keyframe removal."""

from __future__ import annotations

import numpy as np
import pypose as pp
import pytest
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.correspondence import get_correspondence_source
from droidw_cli.errors import ConfigError
from droidw_cli.geometry.camera import BA_SCALE, scale_intrinsics
from droidw_cli.geometry.poses import compose, interpolate
from droidw_cli.io.prepare import FramePreparer
from droidw_cli.slam.filler import TrajectoryFiller
from droidw_cli.slam.frontend import Frontend
from droidw_cli.synth import SynthConfig, build_scene

A, B = 120, 132  # two keyframes of the generator's static hand-held walk, 12 frames apart


@pytest.fixture(scope="module")
def walk():
    """Working images, exact 1/8-grid disparities and world-to-camera poses of frames A..B."""
    cfg = SynthConfig.preset("walk-static", seed=1)
    scene = build_scene(cfg)
    prep = FramePreparer((cfg.height, cfg.width), np.asarray(cfg.intrinsics, dtype=np.float64), 196608, None)
    frames = {}
    for k in range(A, B + 1):
        f = scene.frame(k)
        image, depth = prep(f.rgb, f.depth)
        h, w = image.shape[0] // BA_SCALE, image.shape[1] // BA_SCALE
        inv = (1.0 / np.maximum(depth, 1e-3)).reshape(h, BA_SCALE, w, BA_SCALE).mean(axis=(1, 3))
        w2c = pp.mat2SE3(torch.tensor(np.linalg.inv(scene.pose(np.array([k]))[0]), dtype=torch.float64)).tensor().float()
        frames[k] = (image, torch.from_numpy(inv).float(), w2c)
    k8 = torch.tensor(scale_intrinsics(np.asarray(prep.intrinsics, dtype=np.float64), BA_SCALE), dtype=torch.float32)
    return frames, k8


def _frontend(walk, keyframes):
    frames, k8 = walk
    cfg = load_config("default", ["uncertainty.enable=false"])
    image = frames[keyframes[0]][0]
    grid = (image.shape[0] // BA_SCALE, image.shape[1] // BA_SCALE)
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), get_correspondence_source(cfg.correspondence), grid, k8, 0)
    for k in keyframes:
        img, disp, pose = frames[k]
        fe.buffer.append(k, k / 30.0, pose, disp, img[::8, ::8])
        fe.images[len(fe.buffer) - 1] = img
    fe.initialised = True
    return fe, cfg


def _centre(w2c: torch.Tensor) -> torch.Tensor:
    return pp.SE3(w2c).Inv().tensor()[..., :3]


def test_two_sided_refinement_beats_interpolation(walk):
    """With exact keyframe depths, the filler's camera centres are closer to the truth than SE(3) interpolation."""
    frames, _ = walk
    fe, cfg = _frontend(walk, [A, B])
    filler = TrajectoryFiller(fe, cfg.filler)
    for k in range(A + 1, B):
        filler.add_frame(k, k / 30.0, A, frames[k][0])
    filler.update()  # anchor A is only one keyframe old: lag 2 keeps its gap pending
    assert filler._pending
    poses = filler.finish()
    interp = TrajectoryFiller(fe, load_config("default", ["filler.iters=0"]).filler)
    for k in range(A + 1, B):
        interp.add_frame(k, k / 30.0, A, frames[k][0])
    flat = interp.finish()
    err = [float((_centre(poses[k]) - _centre(frames[k][2])).norm()) for k in range(A + 1, B)]
    err0 = [float((_centre(flat[k]) - _centre(frames[k][2])).norm()) for k in range(A + 1, B)]
    assert set(poses) == set(range(A, B + 1))
    assert np.median(err) < 0.6 * np.median(err0), (np.median(err), np.median(err0))


def test_removed_keyframe_becomes_a_frame_of_its_predecessor(walk):
    """Keyframe removal keeps the chain: a later rigid motion of the remaining keyframes carries every frame."""
    frames, _ = walk
    mid = (A + B) // 2

    def removed_middle():
        fe, cfg = _frontend(walk, [A, mid, B])
        filler = TrajectoryFiller(fe, cfg.filler)
        for k in range(A + 1, B):
            if k != mid:
                filler.add_frame(k, k / 30.0, A if k < mid else mid, frames[k][0])
        filler.keyframe_removed(1)  # what the frontend calls just before dropping keyframe 1
        fe._remove(1)
        return fe, filler

    before = removed_middle()[1].finish()
    fe2, filler2 = removed_middle()
    shift = torch.tensor([0.3, -0.1, 0.2, 0.0, 0.0, 0.0, 1.0])  # the world moves: G_t → G_t S⁻¹ for all
    s_inv = pp.SE3(shift).Inv().tensor()
    fe2.buffer.poses[:2] = compose(fe2.buffer.poses[:2], s_inv.expand(2, 7))
    after = filler2.finish()
    assert set(before) == set(range(A, B + 1)) == set(after)
    for k in range(A, B + 1):
        expected = compose(before[k], s_inv)
        assert torch.allclose(after[k], expected, atol=1e-4) or torch.allclose(after[k], -expected, atol=1e-4)
    assert float((_centre(before[mid]) - _centre(frames[mid][2])).norm()) < 1e-4  # the removed keyframe keeps its pose


def test_a_removed_keyframe_merges_its_gap_and_stays_a_knot_of_the_interpolation(walk):
    """Removal right after a new keyframe: the removed keyframe's frames wait for the predecessor's gap
    (solved later against settled keyframes), whose starting poses pass through the removed keyframe's pose."""
    frames, _ = walk
    mid = (A + B) // 2
    fe, _ = _frontend(walk, [A, mid, B])
    bump = torch.tensor([0.05, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])  # the removed keyframe 5 cm off the A-B line
    fe.buffer.poses[1] = compose(bump, fe.buffer.poses[1])
    kept_mid = fe.buffer.poses[1].clone()
    filler = TrajectoryFiller(fe, load_config("default", ["filler.iters=0"]).filler)
    for k in range(A + 1, B):
        if k != mid:
            filler.add_frame(k, k / 30.0, A if k < mid else mid, frames[k][0])
    filler.keyframe_removed(1)
    fe._remove(1)
    assert sorted(p.frame_index for p in filler._pending[A]) == [k for k in range(A + 1, B) if k != mid]
    poses = filler.finish()
    ends = {A: frames[A][2], mid: kept_mid, B: frames[B][2]}
    for k in (mid - 2, mid + 3):
        lo, hi = (A, mid) if k < mid else (mid, B)
        alpha = torch.tensor([(k - lo) / (hi - lo)])
        piecewise = interpolate(ends[lo][None], ends[hi][None], alpha)[0]
        straight = interpolate(ends[A][None], ends[B][None], torch.tensor([(k - A) / (B - A)]))[0]
        assert float((_centre(poses[k]) - _centre(piecewise)).norm()) < 1e-4
        assert float((_centre(poses[k]) - _centre(straight)).norm()) > 0.01


def test_uninitialised_frames_stay_at_their_keyframe(walk):
    """Before initialisation nothing is solved; a run that never initialises leaves every frame at its anchor."""
    frames, _ = walk
    fe, cfg = _frontend(walk, [A])
    fe.initialised = False
    filler = TrajectoryFiller(fe, cfg.filler, max_pending=3)
    for k in range(A + 1, A + 6):
        filler.add_frame(k, k / 30.0, A, frames[k][0])
    assert filler._stored == 3  # images kept only up to max_pending before initialisation
    filler.update()
    poses = filler.finish()
    for k in range(A, A + 6):
        assert torch.allclose(poses[k], frames[A][2], atol=1e-5)


def test_a_later_correction_between_the_keyframes_is_spread_over_the_gap(walk):
    """When the BA moves b relative to a after the gap was solved, a frame follows both: the blend by α."""
    frames, _ = walk
    fe, cfg = _frontend(walk, [A, B])
    filler = TrajectoryFiller(fe, cfg.filler)
    for k in range(A + 1, B):
        filler.add_frame(k, k / 30.0, A, frames[k][0])
    filler._solve(0)
    before = filler.finish()
    step = torch.tensor([0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 1.0])  # b moves 12 cm along its optical axis
    fe.buffer.poses[1] = compose(step, fe.buffer.poses[1])
    after = filler.finish()
    for k in range(A + 1, B):
        alpha = (k - A) / (B - A)
        moved = float((_centre(after[k]) - _centre(before[k])).norm())
        assert abs(moved - alpha * 0.12) < 0.01, (k, moved, alpha)


def test_flows_computed_ahead_give_the_same_poses(walk):
    """The worker thread changes when the flows run, not what they are: the same poses as synchronous flows."""
    frames, _ = walk
    mid = (A + B) // 2

    def run(ahead: bool):
        fe, cfg = _frontend(walk, [A, mid])
        if not ahead:
            fe.correspondence.concurrent_quick_target = False  # an instance attribute: this source only
        filler = TrajectoryFiller(fe, cfg.filler)
        assert filler._targets.ahead == ahead
        for k in range(A + 1, mid):
            filler.add_frame(k, k / 30.0, A, frames[k][0])
        for k in (mid, B):  # b = mid arrives (its flows start), then B makes A's gap two keyframes old
            if k == B:
                img, disp, pose = frames[B]
                fe.buffer.append(B, B / 30.0, pose, disp, img[::8, ::8])
                fe.images[len(fe.buffer) - 1] = img
            filler.update()
        assert not filler._pending and not filler._targets._jobs
        return filler.finish()

    ahead, sync = run(True), run(False)
    assert set(ahead) == set(sync)
    for k in ahead:
        assert torch.equal(ahead[k], sync[k]), k


def test_a_refined_pose_may_leave_the_interpolation_only_by_a_share_of_the_baseline(walk):
    """filler.max_departure bounds how far a refined camera centre may leave the interpolated one."""
    frames, _ = walk

    def centres(*overrides):
        fe, _ = _frontend(walk, [A, B])
        filler = TrajectoryFiller(fe, load_config("default", list(overrides)).filler)
        for k in range(A + 1, B):
            filler.add_frame(k, k / 30.0, A, frames[k][0])
        poses = filler.finish()
        return torch.stack([_centre(poses[k]) for k in range(A + 1, B)])

    interpolated = centres("filler.iters=0")
    free = centres("filler.max_departure=0")
    tight = centres("filler.max_departure=0.000001")
    baseline = float((_centre(frames[B][2]) - _centre(frames[A][2])).norm())
    assert torch.allclose(tight, interpolated, atol=1e-6)
    assert float((free - interpolated).norm(dim=1).max()) > 0.01 * baseline  # the refinement moved some frames
    bounded = centres("filler.max_departure=0.02")
    departure = (bounded - interpolated).norm(dim=1)
    assert float(departure.max()) <= 0.02 * baseline + 1e-6


def test_the_refined_share_blends_between_min_gain_and_blend_gain(walk):
    """λ is 1 at or below min_gain, 0 at or above blend_gain, linear between; blend_gain ≤ min_gain is a hard cut."""
    fe, _ = _frontend(walk, [A, B])
    start = torch.ones(6)
    final = torch.tensor([0.1, 0.4, 0.5, 0.6, 0.8, 1.2])
    soft = TrajectoryFiller(fe, load_config("default", ["filler.min_gain=0.4", "filler.blend_gain=0.8"]).filler)
    assert torch.allclose(soft._refined_share(final, start), torch.tensor([1.0, 1.0, 0.75, 0.5, 0.0, 0.0]))
    hard = TrajectoryFiller(fe, load_config("default", ["filler.min_gain=0.5", "filler.blend_gain=0"]).filler)
    assert hard._refined_share(final, start).tolist() == [1.0, 1.0, 0.0, 0.0, 0.0, 0.0]
    assert soft._refined_share(torch.zeros(1), torch.zeros(1)).tolist() == [0.0]  # nothing measured: interpolate


def test_filler_gains_must_not_be_negative():
    with pytest.raises(ConfigError, match="min_gain"):
        load_config("default", ["filler.min_gain=-0.1"])


def test_smoothing_spreads_a_single_departure_over_its_neighbours():
    """One pass of [1 2 1]/4 over the departures Log(G_t G_int,t⁻¹), zero at the gap's keyframes."""
    from droidw_cli.geometry.poses import log_departure, retract
    from droidw_cli.slam.filler import smooth_departures

    torch.manual_seed(0)
    init = pp.randn_SE3(5, sigma=0.3).tensor()
    spike = torch.zeros(5, 6)
    spike[2] = torch.tensor([0.02, -0.01, 0.03, 0.004, -0.002, 0.003])
    poses = retract(spike, init)
    assert torch.allclose(log_departure(poses, init), spike, atol=1e-6)
    out = log_departure(smooth_departures(init, poses, 1, closed=True), init)
    assert torch.allclose(out, torch.stack([0 * spike[2], spike[2] / 4, spike[2] / 2, spike[2] / 4, 0 * spike[2]]), atol=1e-6)
    assert torch.equal(smooth_departures(init, poses, 0, closed=True), poses)  # off
    edge = torch.zeros(5, 6)
    edge[4] = spike[2]
    open_end = log_departure(smooth_departures(init, retract(edge, init), 1, closed=False), init)
    assert torch.allclose(open_end[4], 0.75 * spike[2], atol=1e-6)  # an open gap's last frame repeats itself
    assert torch.allclose(open_end[3], 0.25 * spike[2], atol=1e-6)
    assert torch.allclose(smooth_departures(init, init, 2, closed=True), init, atol=1e-6)  # nothing to smooth


def test_filler_smoothing_passes_must_not_be_negative():
    with pytest.raises(ConfigError, match="smooth"):
        load_config("default", ["filler.smooth=-1"])


def test_unmeasured_frames_take_the_departures_interpolated_in_time():
    """filler.stride: frames between measured ones take their departures linearly in time, zero at the keyframes."""
    from droidw_cli.geometry.poses import log_departure, retract
    from droidw_cli.slam.filler import between_departures

    torch.manual_seed(1)
    init = pp.randn_SE3(5, sigma=0.3).tensor()
    ts = torch.tensor([1.0, 2.0, 3.0, 4.0, 5.0], dtype=torch.float64)  # keyframes at t 0 and 6
    d1 = torch.tensor([0.02, -0.01, 0.03, 0.004, -0.002, 0.003])
    d3 = torch.tensor([-0.01, 0.02, 0.0, 0.0, 0.001, -0.002])
    refined = retract(torch.stack([d1, d3]), init[[1, 3]])
    out = log_departure(between_departures(init, refined, [1, 3], ts, 0.0, 6.0), init)
    assert torch.allclose(out[0], d1 / 2, atol=1e-6)  # halfway between the keyframe (0) and frame 1
    assert torch.allclose(out[2], (d1 + d3) / 2, atol=1e-6)
    assert torch.allclose(out[4], d3 / 2, atol=1e-6)  # t 5 halfway between t 4 (d3) and the keyframe at 6
    assert torch.allclose(out[[1, 3]], torch.zeros(2, 6), atol=1e-6)  # the measured ones are left to the caller
    open_gap = log_departure(between_departures(init, refined, [1, 3], ts, 0.0, None), init)
    assert torch.allclose(open_gap[4], d3, atol=1e-6)  # an open gap holds its last measured departure


def test_filler_stride_keeps_only_every_s_th_image(walk):
    frames, _ = walk
    fe, _ = _frontend(walk, [A, B])
    filler = TrajectoryFiller(fe, load_config("default", ["filler.stride=3"]).filler)
    for k in range(A + 1, B):
        filler.add_frame(k, k / 30.0, A, frames[k][0])
    kept = [p.frame_index for p in filler._pending[A] if p.image is not None]
    assert kept == [A + 3, A + 6, A + 9]
    poses = filler.finish()
    assert set(poses) == set(range(A, B + 1))
    with pytest.raises(ConfigError, match="stride"):
        load_config("default", ["filler.stride=0"])
