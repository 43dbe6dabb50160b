"""``droidw track`` on the real clips in ../shared/data (skipped when absent)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from droidw_cli.cli import main
from droidw_cli.io.trajectory import read_trajectory


def _track(*args):
    try:
        main(["track", *map(str, args), "--quiet"])
    except SystemExit as exc:
        assert exc.code in (0, None), f"droidw track exited with {exc.code}"


def test_fixed_camera_gives_identity_and_warns(shared_data, tmp_path, capsys):
    """vtest.avi: a fixed camera watching pedestrians must not invent camera motion."""
    out = tmp_path / "vtest"
    _track(shared_data / "real" / "vtest" / "vtest.avi", "--out", out, "--calib", "auto")
    traj = read_trajectory(out / "traj.txt")
    assert len(traj) == 795
    deviation = np.abs(traj.poses - np.eye(4)).max()
    assert deviation < 1e-3, f"invented motion: {deviation}"
    assert "parallax" in capsys.readouterr().err
    info = json.loads((out / "run.json").read_text())
    assert "parallax" in " ".join(info["warnings"])
    assert info["calibration"]["source"] == "guessed"  # nothing to estimate the focal length from


@pytest.mark.parametrize("clip, frames, extra", [
    ("lady-running.mp4", 65, ()),
    ("bedroom", 200, ("--set", "uncertainty.enable=false")),  # the longer clip without XFeat keeps the suite short
])
def test_real_clips_finish_with_a_pose_per_frame(shared_data, tmp_path, clip, frames, extra):
    out = tmp_path / "run"
    _track(shared_data / "real" / clip, "--out", out, "--calib", "auto", "--config", "fast", *extra)
    traj = read_trajectory(out / "traj.txt")
    assert len(traj) == frames
    assert np.all(np.isfinite(traj.poses))
    info = json.loads((out / "run.json").read_text())
    assert info["calibration"]["source"] == "estimated" and info["calibration"]["fx"] > 0
