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
