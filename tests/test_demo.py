"""`droidw demo`, the README's main job, as a new user runs it (defaults, one run to keep it short)."""

from __future__ import annotations

import re

from cli_run import run


def test_demo_with_its_defaults_tracks_the_scene(tmp_path, capsys):
    code, out, err = run(["demo", "--out", str(tmp_path / "demo"), "--no-baseline", "--quiet"], capsys)
    assert code == 0, err
    row = re.search(r"uncertainty on\s+([\d.]+)\s+([\d.]+)\s+(\d+)", out)
    assert row, out
    ate_cm, keyframes = float(row.group(1)), int(row.group(3))
    assert keyframes >= 3  # initialised: a run that never initialises keeps one or two
    assert ate_cm < 2.0  # 0.55 cm measured
    assert (tmp_path / "demo" / "run" / "traj.txt").is_file()


def test_demo_runs_again_and_says_when_a_clip_is_too_short(tmp_path, capsys):
    out_dir = str(tmp_path / "demo")
    base = ["demo", "--out", out_dir, "--no-baseline", "--quiet", "--frames", "6"]
    code, out, err = run(base, capsys)
    assert code == 0, err
    assert re.search(r"uncertainty on\s+–\s+[\d.]+\s+\d+", out), out  # never initialised: no ATE, no traceback
    assert "never initialised" in out
    stamp = (tmp_path / "demo" / "sequence" / "synth.json").stat().st_mtime_ns
    code, out, err = run(base, capsys)  # the README's main job, run a second time
    assert code == 0, err
    assert "reusing" in out and (tmp_path / "demo" / "sequence" / "synth.json").stat().st_mtime_ns == stamp
    code, out, err = run(base[:-1] + ["7"], capsys)  # other settings: the old sequence is not silently replaced
    assert code == 2 and "--overwrite" in err
    code, out, err = run(base[:-1] + ["7", "--overwrite"], capsys)
    assert code == 0, err
    assert "generating 7 frames" in out
