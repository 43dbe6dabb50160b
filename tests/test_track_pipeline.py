"""End-to-end ``droidw track`` on short synthetic sequences with exact ground truth.

The full-size (300-frame, 640×480) acceptance runs live in
``benchmarks/track_bench.py``; here the sequences are short and small so the
suite stays fast, with the same thresholds.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from droidw_cli.ba.registry import resolve_backend
from droidw_cli.cli import main
from droidw_cli.eval import evaluate_ate
from droidw_cli.io.trajectory import read_trajectory
from droidw_cli.synth import SynthConfig, write_sequence

# Small working size and a livelier camera, so a short clip still has parallax.
SMALL = ("io.target_area=76800",)


@pytest.fixture(scope="module")
def static_seq(tmp_path_factory):
    cfg = SynthConfig.preset("static", width=320, height=240, frames=70, seed=2, camera_speed=2.5)
    return write_sequence(cfg, tmp_path_factory.mktemp("seq") / "static", progress=False)


def _track(args, capsys=None):
    with pytest.raises(SystemExit) as exc:
        main(["track", *args, "--quiet"])
    return exc.value.code


def _run(seq, out, *extra):
    args = [str(seq), "--out", str(out)]
    for s in SMALL:
        args += ["--set", s]
    args += list(extra)
    try:
        main(["track", *args, "--quiet"])
    except SystemExit as exc:  # click's standalone mode is off; main exits only on errors
        assert exc.code in (0, None), f"droidw track exited with {exc.code}"
    return out


@pytest.fixture(scope="module")
def static_run(static_seq, tmp_path_factory):
    return _run(static_seq, tmp_path_factory.mktemp("run") / "static", "--set", "uncertainty.enable=false")


def test_static_known_calibration_ate_bounded(static_seq, static_run):
    gt = read_trajectory(static_seq / "groundtruth.txt")
    est = read_trajectory(static_run / "traj.txt")
    assert len(est) == len(gt)  # one pose for every frame, with the input's timestamps
    np.testing.assert_allclose(est.timestamps, gt.timestamps, atol=1e-6)
    ate = evaluate_ate(gt, est, align="sim3")
    # 1.00 cm with the online filler (FAST flow; interpolation alone 3.32 cm) on this 70-frame clip of
    # 7 keyframes at 240×320; the 450-frame presets are judged by benchmarks/track_bench.py
    assert ate.rmse < 0.0125, f"ATE {ate.rmse * 100:.2f} cm"


def test_run_folder_contents(static_run):
    info = json.loads((static_run / "run.json").read_text())
    assert info["frames"] == 70 and 3 <= info["keyframes"] < 35 and info["initialised"] is True
    # --backend auto (the default): cuda on a machine with a GPU, else native where it builds, else cpu (its
    # stderr line and run.json say which)
    assert info["backend"] == resolve_backend("auto").name
    assert info["backend_choice"]["requested"] == "auto"
    assert info["fps"] > 0 and info["peak_memory_mb"] > 0
    assert {"decode", "flow", "ba", "filler"} <= set(info["seconds_per_stage"])
    with np.load(static_run / "keyframes.npz") as z:
        assert {"index", "timestamps", "poses_c2w", "disps", "intrinsics", "images", "confidence"} <= set(z.files)
        assert z["disps"].shape[1:] == (30, 40) and len(z["index"]) == info["keyframes"]
    calib = np.loadtxt(static_run / "calib.txt", comments="#")
    np.testing.assert_allclose(calib[:4], [262.5, 262.5, 159.5, 119.5], rtol=1e-6)
    assert not list(static_run.glob(".droidw-*"))  # no temporary folder left behind


def test_same_input_same_trajectory_bytes(static_seq, static_run, tmp_path):
    again = _run(static_seq, tmp_path / "again", "--set", "uncertainty.enable=false")
    assert (again / "traj.txt").read_bytes() == (static_run / "traj.txt").read_bytes()


def test_auto_calibration_focal_within_3_percent(static_seq, tmp_path):
    out = _run(static_seq, tmp_path / "auto", "--calib", "auto", "--set", "uncertainty.enable=false")
    info = json.loads((out / "run.json").read_text())
    assert info["calibration"]["source"] == "estimated"
    f = info["calibration"]["fx"]
    assert abs(f / 262.5 - 1) < 0.03, f"estimated f = {f:.1f}, true 262.5"
    ate = evaluate_ate(read_trajectory(static_seq / "groundtruth.txt"), read_trajectory(out / "traj.txt"))
    assert ate.rmse < 0.02


def test_user_errors_exit_2_without_output(tmp_path, static_seq, capsys):
    assert _track([str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "o1")]) == 2
    err = capsys.readouterr().err
    assert "missing.mp4" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    bad = tmp_path / "calib.txt"
    bad.write_text("500 500 900 120\n")  # cx outside a 320-pixel-wide image
    assert _track([str(static_seq), "--calib", str(bad), "--out", str(tmp_path / "o2")]) == 2
    assert "cx" in capsys.readouterr().err
    assert not (tmp_path / "o2" / "traj.txt").exists()
    assert _track([str(static_seq), "--set", "frontend.windw=3", "--out", str(tmp_path / "o3")]) == 2
    assert "frontend.windw" in capsys.readouterr().err


def test_matching_ahead_changes_nothing_but_the_timing(static_seq, static_run, tmp_path, monkeypatch):
    """Each new keyframe's pair to the previous one is matched on another thread (slam/scout.py),
    and taken from there: the trajectory is the same bytes as with every match on the main thread."""
    from droidw_cli.slam.scout import Scout

    used = []
    matched = Scout.matched

    def counted(self, i, j):
        result = matched(self, i, j)
        used.append(result is not None)
        return result

    monkeypatch.setattr(Scout, "matched", counted)
    ahead = _run(static_seq, tmp_path / "ahead", "--set", "uncertainty.enable=false")
    assert sum(used) >= 2
    assert (ahead / "traj.txt").read_bytes() == (static_run / "traj.txt").read_bytes()
    used.clear()
    off = _run(static_seq, tmp_path / "off", "--set", "uncertainty.enable=false", "--set", "frontend.match_ahead=false")
    assert not used
    assert (off / "traj.txt").read_bytes() == (static_run / "traj.txt").read_bytes()


def test_auto_calibration_on_a_fixed_camera_says_it_guessed(tmp_path, capsys):
    """No rotation, nothing to estimate f from: run.json and the output say the focal length is a guess."""
    cfg = SynthConfig.preset("fixed", width=160, height=120, frames=20, seed=1)
    seq = write_sequence(cfg, tmp_path / "fixed", progress=False)
    (seq / "calib.txt").unlink()
    out = _run(seq, tmp_path / "auto", "--calib", "auto", "--set", "uncertainty.enable=false")
    captured = capsys.readouterr()
    info = json.loads((out / "run.json").read_text())
    assert info["calibration"]["source"] == "guessed"
    assert "focal length was not estimated" in " ".join(info["warnings"])
    assert "guessed (not estimated) calibration" in captured.out
