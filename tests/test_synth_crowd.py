"""Walkers keep apart (synth.crowd): no two bodies pass through each other."""

import json

import numpy as np
import pytest

from droidw_cli.synth import SynthConfig, build_scene, write_sequence
from droidw_cli.synth import crowd
from droidw_cli.synth.config import GENERATOR_VERSION
from droidw_cli.synth.paths import make_walk

ROOM = np.array([5.5, 4.9, 2.6])


def _paths(walks, t):
    return [w.state(t)[1][:, :2] for w in walks]


@pytest.mark.parametrize("preset, seed", [("rotate", 2), ("rotate", 4), ("fixed", 1), ("wobble", 4), ("walk", 1)])
def test_preset_walkers_keep_apart_at_every_frame(preset, seed):
    # without ``apart`` these scenes have walkers meeting (within 0.01-0.4 m); rotate seed 1, not here, keeps
    # 0.54 m: its fourth walker finds no loop 0.7 m clear within the coverage caps
    cfg = SynthConfig.preset(preset, seed=seed, apart=True)
    scene = build_scene(cfg)
    t = scene.walker_time(np.arange(cfg.frames))
    paths = _paths([w.walk for w in scene.walkers], t)
    assert len(paths) == cfg.movers
    for i in range(len(paths)):
        for j in range(i):
            assert np.linalg.norm(paths[i] - paths[j], axis=1).min() >= crowd.CLEARANCE


def test_walkers_on_one_loop_are_drawn_apart_and_away_from_the_camera():
    t = np.arange(300) / 30.0
    cam = np.stack([0.3 * np.sin(t), 1.0 + 0.1 * np.cos(t)], 1)
    first = make_walk((0.0, 3.3), (1.0, 0.0), 1.2, 0.4, 1.0, 1, 0.0, 0.0)
    twin = make_walk((0.0, 3.3), (1.0, 0.0), 1.2, 0.4, 1.0, 1, 0.1, 0.0)  # 0.1 rad behind on the same loop
    out = crowd.keep_apart([first, twin], t, cam, ROOM, seed=5)
    assert out[0] is first and out[1] is not twin
    a, b = _paths(out, t)
    assert np.linalg.norm(a - b, axis=1).min() >= crowd.CLEARANCE
    assert np.linalg.norm(b - cam, axis=1).min() >= crowd.CAMERA_GAP
    again = crowd.keep_apart([first, twin], t, cam, ROOM, seed=5)
    assert again[1] == out[1]  # the same seed draws the same walk


def test_walkers_that_keep_apart_keep_their_loops():
    t = np.arange(300) / 30.0
    cam = np.zeros((300, 2))
    left = make_walk((-1.2, 3.3), (1.0, 0.0), 0.4, 0.3, 1.0, 1, 0.0, 0.0)
    right = make_walk((1.2, 3.3), (1.0, 0.0), 0.4, 0.3, 1.0, -1, 2.0, 0.0)
    out = crowd.keep_apart([left, right], t, cam, ROOM, seed=0)
    assert out[0] is left and out[1] is right
    assert 2.4 - 0.8 - 1e-9 <= crowd.min_gap(out, t) <= 2.4  # the loops' inner ends are 1.6 m apart
    assert crowd.min_gap([left], t) == float("inf")


def test_a_refused_walker_is_not_taken():
    t = np.arange(300) / 30.0
    cam = np.stack([np.zeros(300), np.ones(300)], 1)
    first = make_walk((0.0, 3.3), (1.0, 0.0), 1.2, 0.4, 1.0, 1, 0.0, 0.0)
    twin = make_walk((0.0, 3.3), (1.0, 0.0), 1.2, 0.4, 1.0, 1, 0.1, 0.0)
    taken = crowd.keep_apart([first, twin], t, cam, ROOM, seed=5)[1]
    seen = []

    def admits(walks):
        seen.append(walks[1])
        return walks[1] != taken  # refuse the walk that would have been taken
    other = crowd.keep_apart([first, twin], t, cam, ROOM, seed=5, admits=admits)[1]
    assert taken in seen and other != taken
    assert crowd.min_gap([first, other], t) >= crowd.CLEARANCE


def test_apart_is_opt_in_and_the_default_scenes_do_not_change():
    cfg = SynthConfig.preset("walk", seed=1)
    plain, apart = build_scene(cfg), build_scene(cfg.replace(apart=True))
    t = plain.walker_time(np.arange(cfg.frames))
    assert plain.walkers[0].walk == apart.walkers[0].walk  # walker 0 is placed first and keeps its loop
    assert crowd.min_gap([w.walk for w in plain.walkers], t) < 0.3  # the default walkers pass through each other
    assert crowd.min_gap([w.walk for w in apart.walkers], t) >= crowd.CLEARANCE


def test_written_sequences_record_the_generator_version(tmp_path):
    cfg = SynthConfig.preset("dynamic-small", seed=2, frames=3, apart=True)
    write_sequence(cfg, tmp_path / "seq", progress=False)
    meta = json.loads((tmp_path / "seq" / "synth.json").read_text())
    assert meta["version"] == GENERATOR_VERSION == 1
    assert meta["config"]["seed"] == 2 and meta["config"]["apart"] is True and meta["walkers"] == 3


def test_synth_apart_flag(tmp_path):
    from droidw_cli.cli import main

    main(["synth", str(tmp_path / "seq"), "--preset", "walk", "--frames", "2", "--size", "64x48", "--apart", "--quiet"])
    main(["synth", str(tmp_path / "plain"), "--preset", "walk", "--frames", "2", "--size", "64x48", "--quiet"])
    assert json.loads((tmp_path / "seq" / "synth.json").read_text())["config"]["apart"] is True
    assert json.loads((tmp_path / "plain" / "synth.json").read_text())["config"]["apart"] is False
