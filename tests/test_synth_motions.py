"""Synthetic camera motions (handheld, wobble, rotate, stopgo, fixed), the realistic presets and their CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from droidw_cli.synth import PRESETS, SynthConfig, build_scene
from droidw_cli.synth.config import MOTIONS, STREET_MOTIONS

ROOM_MOTIONS = [m for m in MOTIONS if m not in STREET_MOTIONS]  # streets: test_synth_street.py, test_synth_follow.py

SMALL = {"width": 160, "height": 120}


def _angle(ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    """Rotation angle (degrees) between rotation matrices, broadcast."""
    rel = np.einsum("...ji,...jk->...ik", ra, rb)
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


@pytest.fixture(scope="module")
def paths() -> dict:
    """Static scenes (no walkers) of every motion, 450 frames (15 s), and their poses."""
    out = {}
    for motion in ROOM_MOTIONS:
        sc = build_scene(SynthConfig(motion=motion, static=True, movers=0, frames=450, seed=3, **SMALL))
        out[motion] = (sc, sc.pose(np.arange(450)))
    return out


@pytest.mark.parametrize("motion", ROOM_MOTIONS)
def test_every_motion_gives_valid_smooth_poses_inside_the_room(paths, motion):
    sc, poses = paths[motion]
    rot = poses[:, :3, :3]
    np.testing.assert_allclose(np.einsum("nji,njk->nik", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)
    np.testing.assert_array_equal(poses[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (450, 4)))
    step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    assert step.max() < 0.04  # no jumps
    assert _angle(rot[:-1], rot[1:]).max() < 4.0
    room = sc.room
    assert np.all(np.abs(poses[:, 0, 3]) < room[0] / 2 - 0.5) and np.all(poses[:, 1, 3] > 0.3)
    for k in range(0, 450, 45):  # the view stays inside the room: no wall right in front of the lens
        depth = sc.render(k)[1]
        assert depth.min() > 0.8 and np.median(depth) > 1.5
    # the same seed gives the same path; the walker tuning reads it through position/target
    again = build_scene(sc.cfg).pose(np.arange(0, 450, 7))
    np.testing.assert_array_equal(again, poses[::7])
    cam = sc.camera
    t = sc.camera_time(np.arange(0, 450, 50))
    np.testing.assert_array_equal(cam.position(t), poses[::50, :3, 3])
    fwd = cam.target(t) - cam.position(t)
    assert np.all(np.einsum("ni,ni->n", fwd / np.linalg.norm(fwd, axis=1, keepdims=True), poses[::50, :3, 2]) > 0.9)


def test_wobble_is_a_near_still_hand(paths):
    _, poses = paths["wobble"]
    pos = poses[:, :3, 3]
    spread = np.linalg.norm(pos[:, None] - pos[None], axis=-1).max()
    assert 0.02 < spread < 0.10  # a few centimetres in all
    rot = poses[::3, :3, :3]
    assert 5.0 <= _angle(rot[:, None], rot[None]).max() <= 10.0  # ~7° peak to peak
    assert np.any(np.abs(np.diff(pos, axis=0)) > 0)  # never exactly still


def test_rotate_turns_fast_on_the_spot(paths):
    _, poses = paths["rotate"]
    pos = poses[:, :3, 3]
    assert np.linalg.norm(pos - pos.mean(0), axis=1).max() < 0.15
    speed = _angle(poses[:-1, :3, :3], poses[1:, :3, :3]) * 30.0  # degrees per second
    assert 40.0 < speed.max() < 150.0
    assert np.mean(speed > 20.0) > 0.5  # fast most of the time, not a single spike
    rot = poses[::3, :3, :3]
    assert _angle(rot[:, None], rot[None]).max() > 50.0


def test_stopgo_stops_completely_and_starts_again(paths):
    sc, poses = paths["stopgo"]
    step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    still = np.all(poses[1:] == poses[:-1], axis=(1, 2))  # bit-identical poses
    assert 0.2 < still.mean() < 0.5  # stops of ~1.5-2 s twice per ~10 s
    assert np.mean(step > 0.003) > 0.35  # and moves in between
    # contiguous stops, each 1.2-2.2 s long (the ones cut by the sequence ends aside)
    edges = np.flatnonzero(np.diff(still.astype(int)))
    runs = np.diff(edges)[::2] if still[edges[0] + 1] else np.diff(edges)[1::2]
    assert len(runs) >= 2 and np.all((runs >= 36) & (runs <= 66))
    # the same path as handheld, at warped time: every pose lies on the handheld path
    hand = build_scene(sc.cfg.replace(motion="handheld"))
    tau = sc.camera.warp(sc.camera_time(np.arange(450)))
    np.testing.assert_allclose(hand.camera.pose(tau), poses, atol=1e-12)
    assert np.all(np.diff(tau) >= 0)


def test_fixed_camera_does_not_move(paths):
    sc, poses = paths["fixed"]
    assert np.array_equal(poses, np.broadcast_to(poses[0], poses.shape))
    np.testing.assert_array_equal(sc.pose(17), poses[0])
    a, b = sc.frame(0), sc.frame(300)
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)


@pytest.mark.parametrize("motion", ROOM_MOTIONS)
def test_walkers_are_tuned_for_every_motion(motion):
    cfg = SynthConfig(motion=motion, movers=2, frames=150, seed=1, **SMALL)
    sc = build_scene(cfg)
    cover = np.array([sc.render(k)[2].mean() for k in range(0, cfg.frames, 3)])
    assert 0.15 <= cover.max() <= 0.6
    assert np.mean(cover > 0.01) > 0.4


def test_wobble_preset_walker_crosses_close():
    cfg = SynthConfig.preset("wobble", seed=0, **SMALL)
    sc = build_scene(cfg)
    ks = np.arange(0, cfg.frames, 3)
    _, pos = sc.walkers[0].walk.state(sc.walker_time(ks))
    dist = np.linalg.norm(pos[:, :2] - sc.pose(ks)[:, :2, 3], axis=1)
    assert 0.45 <= dist.min() <= 0.95
    cover = np.array([sc.render(k, movers=True)[2].mean() for k in ks])
    assert 0.35 <= cover.max() <= 0.55


def test_new_presets_and_validation():
    expect = {
        "walk": {"motion": "handheld", "movers": 2, "blur": 0.4, "jpeg_quality": 75, "noise_std": 1.5,
                 "gain_drift": 0.08, "frames": 450},
        "walk-static": {"motion": "handheld", "static": True, "blur": 0.4, "frames": 450},
        "wobble": {"motion": "wobble", "movers": 2, "target_coverage": 0.45, "blur": 0.3, "jpeg_quality": 75,
                   "noise_std": 1.5, "frames": 450},
        "rotate": {"motion": "rotate", "movers": 4, "blur": 0.5, "jpeg_quality": 60, "noise_std": 2.0,
                   "gain_drift": 0.1, "frames": 450},
        "stopgo": {"motion": "stopgo", "movers": 2, "blur": 0.4, "jpeg_quality": 75, "frames": 450},
        "fixed": {"motion": "fixed", "movers": 3, "jpeg_quality": 75, "noise_std": 1.5, "frames": 300},
    }
    for name, fields in expect.items():
        cfg = SynthConfig.preset(name)
        assert (cfg.width, cfg.height) == (640, 480)
        assert {k: getattr(cfg, k) for k in fields} == fields, name
    assert SynthConfig.preset("walk-static").n_movers == 0
    walk, still = build_scene(SynthConfig.preset("walk", **SMALL)), build_scene(SynthConfig.preset("walk-static", **SMALL))
    np.testing.assert_array_equal(walk.pose(np.arange(450)), still.pose(np.arange(450)))
    for old in ("static", "dynamic", "busy", "static-small", "dynamic-small", "busy-small"):
        cfg = SynthConfig.preset(old)
        assert (cfg.motion, cfg.blur, cfg.jpeg_quality, cfg.gain_drift, cfg.flicker) == ("handheld", 0.0, 0, 0.0, 0.0)
    for bad in ({"motion": "orbit"}, {"blur": 1.5}, {"blur": -0.1}, {"blur_samples": 0}, {"jpeg_quality": 101},
                {"jpeg_quality": -1}, {"gain_drift": 1.0}, {"flicker": -0.01}):
        with pytest.raises(ValueError):
            SynthConfig(**bad)


def test_cli_takes_every_preset_and_the_new_options(tmp_path, capsys):
    from droidw_cli.cli import main
    from droidw_cli.commands.synth import synth

    choices = next(p for p in synth.params if p.name == "preset").type.choices
    assert list(choices) == list(PRESETS)
    out = tmp_path / "rot"
    main(["synth", str(out), "--preset", "rotate", "--frames", "3", "--size", "64x48", "--motion", "stopgo",
          "--blur", "0.2", "--jpeg", "80", "--gain-drift", "0.05", "--noise", "0.5"])
    assert "stopgo camera" in capsys.readouterr().out
    cfg = json.loads((out / "synth.json").read_text())["config"]
    assert (cfg["motion"], cfg["blur"], cfg["jpeg_quality"], cfg["gain_drift"], cfg["noise_std"], cfg["movers"]) == (
        "stopgo", 0.2, 80, 0.05, 0.5, 4)
    assert len(list((out / "rgb").iterdir())) == 3
    main(["synth", str(tmp_path / "fix"), "--preset", "fixed", "--frames", "2", "--size", "64x48", "--quiet"])
    with pytest.raises(SystemExit):
        main(["synth", str(tmp_path / "bad"), "--motion", "orbit", "--quiet"])
