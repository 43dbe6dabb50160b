"""``droidw eval`` on synthetic trajectory files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cli_run import run
from droidw_cli.eval import evaluate_ate, evaluate_rpe
from droidw_cli.io.trajectory import Trajectory, read_trajectory, write_trajectory

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def synthetic_pair(n: int = 120, seed: int = 0) -> tuple[Trajectory, Trajectory]:
    """A smooth ground truth at 30 Hz and a scaled, rotated, noisy estimate with the same stamps."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 30.0
    pos = np.c_[np.sin(0.9 * t), 0.5 * np.cos(0.6 * t), 0.2 * t]
    gt = np.tile(np.eye(4), (n, 1, 1))
    gt[:, :3, 3] = pos
    c, s = np.cos(0.4), np.sin(0.4)
    r = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    est = gt.copy()
    est[:, :3, :3] = r
    est[:, :3, 3] = 0.5 * pos @ r.T + [1.0, 2.0, 3.0] + rng.normal(scale=0.002, size=pos.shape)
    stamps = 1305031102.0 + np.round(t, 6)
    return Trajectory(stamps, gt), Trajectory(stamps.copy(), est)


@pytest.fixture
def files(tmp_path):
    gt, est = synthetic_pair()
    write_trajectory(tmp_path / "gt.txt", gt, "tum")
    write_trajectory(tmp_path / "est.txt", est, "tum")
    return tmp_path


def expected(files, align="sim3"):
    return evaluate_ate(read_trajectory(files / "gt.txt"), read_trajectory(files / "est.txt"), align)


def test_text_output_contains_rmse_matches_and_scale(files, capsys):
    code, out, err = run(["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est.txt")], capsys)
    assert code == 0, err
    ref = expected(files)
    assert f"rmse    {ref.rmse:.6f}" in out
    assert "matched       120 poses" in out
    assert f"scale         {ref.scale:.6f}" in out
    assert ref.scale == pytest.approx(2.0, rel=0.01)


def test_json_output_parses_and_has_rpe(files, capsys):
    argv = ["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est.txt"), "--json", "--rpe", "4",
            "--align", "se3"]
    code, out, _ = run(argv, capsys)
    assert code == 0
    data = json.loads(out)
    ref = expected(files, "se3")
    assert data["ate"]["rmse"] == pytest.approx(ref.rmse, rel=1e-12)
    assert data["matches"] == 120 and data["align"] == "se3" and data["scale"] == 1.0
    rpe = evaluate_rpe(read_trajectory(files / "gt.txt"), read_trajectory(files / "est.txt"), ref, 4)
    assert data["rpe"]["delta"] == 4 and data["rpe"]["pairs"] == rpe.stats.count == 29
    assert data["rpe"]["rmse"] == pytest.approx(rpe.stats.rmse, rel=1e-12)
    assert np.allclose(np.array(data["rotation"]) @ np.array(data["rotation"]).T, np.eye(3))


def test_plot_writes_a_png_atomically(files, capsys):
    png = files / "plots" / "top.png"
    code, out, _ = run(["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est.txt"), "--plot", str(png)],
                       capsys)
    assert code == 0
    assert png.read_bytes()[:8] == PNG_MAGIC
    assert png.stat().st_size > 5000
    assert sorted(p.name for p in png.parent.iterdir()) == ["top.png"]
    assert str(png) in out


def test_run_folder_and_default_est(files, capsys, monkeypatch):
    run_dir = files / "run"
    run_dir.mkdir()
    (run_dir / "traj.txt").write_text((files / "est.txt").read_text())
    code, out, _ = run(["eval", "--gt", str(files / "gt.txt"), "--est", str(run_dir), "--json"], capsys)
    assert code == 0
    assert json.loads(out)["est"] == str(run_dir / "traj.txt")
    monkeypatch.chdir(run_dir)
    code, out, _ = run(["eval", "--gt", str(files / "gt.txt"), "--json"], capsys)
    assert code == 0
    data = json.loads(out)
    assert data["est"] == "traj.txt"
    assert data["ate"]["rmse"] == pytest.approx(expected(files).rmse, rel=1e-12)


def test_kitti_pairs_by_index_and_euroc_gt(files, capsys):
    gt, est = synthetic_pair()
    write_trajectory(files / "gt_kitti.txt", gt, "kitti")
    write_trajectory(files / "est_kitti.txt", est, "kitti")
    write_trajectory(files / "gt.csv", gt, "euroc")
    code, out, _ = run(["eval", "--gt", str(files / "gt_kitti.txt"), "--est", str(files / "est_kitti.txt"), "--json"],
                       capsys)
    assert code == 0
    data = json.loads(out)
    assert data["association"] == "index" and data["matches"] == 120
    assert data["ate"]["rmse"] == pytest.approx(expected(files).rmse, rel=1e-6)
    code, out, _ = run(["eval", "--gt", str(files / "gt.csv"), "--est", str(files / "est.txt"), "--json"], capsys)
    assert code == 0
    assert json.loads(out)["ate"]["rmse"] == pytest.approx(expected(files).rmse, rel=1e-6)
    # a KITTI estimate against a timestamped ground truth needs its times
    code, _, err = run(["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est_kitti.txt")], capsys)
    assert code == 2 and "--est-times" in err
    (files / "times.txt").write_text("\n".join(f"{v:.6f}" for v in est.timestamps) + "\n")
    code, out, _ = run(["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est_kitti.txt"),
                        "--est-times", str(files / "times.txt"), "--json"], capsys)
    assert code == 0 and json.loads(out)["association"] == "timestamp"


def write_est(files, name, stamps, positions):
    poses = np.tile(np.eye(4), (len(stamps), 1, 1))
    poses[:, :3, 3] = positions
    write_trajectory(files / name, Trajectory(np.asarray(stamps, dtype=float), poses), "tum")
    return str(files / name)


def assert_one_line_error(code, out, err, fragment):
    assert code == 2
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("droidw: error:")
    assert fragment in lines[0]


def test_errors_exit_2_with_one_line(files, capsys):
    gt = str(files / "gt.txt")
    t0 = 1305031102.0
    code, out, err = run(["eval", "--gt", str(files / "missing.txt"), "--est", str(files / "est.txt")], capsys)
    assert_one_line_error(code, out, err, "not found")
    code, out, err = run(["eval", "--gt", gt, "--est", str(files / "nope")], capsys)
    assert_one_line_error(code, out, err, "not found")
    late = write_est(files, "late.txt", t0 + 500 + np.arange(10.0), np.random.default_rng(0).normal(size=(10, 3)))
    code, out, err = run(["eval", "--gt", gt, "--est", late], capsys)
    assert_one_line_error(code, out, err, "no overlapping timestamps")
    two = write_est(files, "two.txt", t0 + np.array([0.0, 1.0]), [[0, 0, 0], [1, 0, 0]])
    code, out, err = run(["eval", "--gt", gt, "--est", two], capsys)
    assert_one_line_error(code, out, err, "at least 3")
    line = write_est(files, "line.txt", t0 + np.round(np.arange(20) / 30.0, 6), np.outer(np.arange(20.0), [1, 1, 0]))
    code, out, err = run(["eval", "--gt", gt, "--est", line], capsys)
    assert_one_line_error(code, out, err, "collinear")
    (files / "bad.txt").write_text("1305031102.0 0 0 0 0 0 0 1\n1305031102.1 0 x 0 0 0 0 1\n")
    code, out, err = run(["eval", "--gt", gt, "--est", str(files / "bad.txt")], capsys)
    assert_one_line_error(code, out, err, f"{files / 'bad.txt'}:2")


def test_max_diff_controls_matching(files, capsys):
    gt, est = synthetic_pair()
    shifted = Trajectory(est.timestamps + 0.01, est.poses)
    write_trajectory(files / "shifted.txt", shifted, "tum")
    argv = ["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "shifted.txt"), "--json"]
    code, out, _ = run(argv + ["--max-diff", "0.02"], capsys)
    assert code == 0 and json.loads(out)["matches"] == 120
    code, _, err = run(argv + ["--max-diff", "0.005"], capsys)
    assert code == 2 and "no overlapping timestamps" in err
    code, out, _ = run(argv + ["--max-diff", "0.005", "--t-offset", "-0.01"], capsys)
    assert code == 0 and json.loads(out)["matches"] == 120


def test_save_results_is_read_by_evo_res(files, capsys):
    import os
    import subprocess
    import sys
    from pathlib import Path

    file_interface = pytest.importorskip("evo.tools.file_interface")
    zip_path = files / "res" / "droidw.zip"
    argv = ["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est.txt"), "--save-results", str(zip_path)]
    code, out, err = run(argv, capsys)
    assert code == 0, err
    assert f"evo results written to {zip_path}" in out
    assert sorted(p.name for p in zip_path.parent.iterdir()) == ["droidw.zip"]
    res = file_interface.load_res_file(zip_path)
    ref = expected(files)
    assert res.stats["rmse"] == pytest.approx(ref.rmse, rel=1e-12)
    assert res.info["est_name"] == str(files / "est.txt") and res.info["ref_name"] == str(files / "gt.txt")
    assert res.np_arrays["error_array"].shape == (120,)
    assert "Sim(3)" in res.info["title"]
    evo_res = Path(sys.executable).parent / "evo_res"
    if evo_res.is_file():  # evo's own command line reads it back
        proc = subprocess.run([str(evo_res), str(zip_path), "--no_warnings"], capture_output=True, text=True,
                              timeout=120, env={**os.environ, "MPLBACKEND": "Agg"})
        assert proc.returncode == 0, proc.stderr
        assert f"{ref.rmse:.6f}" in proc.stdout


def test_plot_uses_evo_top_view_with_error_colours(files, capsys):
    pytest.importorskip("evo.tools.plot")
    import matplotlib

    png = files / "top.png"
    code, _, err = run(["eval", "--gt", str(files / "gt.txt"), "--est", str(files / "est.txt"), "--plot", str(png),
                        "--align", "se3"], capsys)
    assert code == 0, err
    assert png.read_bytes()[:8] == PNG_MAGIC
    assert matplotlib.get_backend().lower() == "agg"
    import cv2

    img = cv2.imread(str(png))
    # evo's colour bar (the jet map) puts saturated red and blue pixels in the picture
    b, g, r = (img[..., k].astype(int) for k in range(3))
    assert ((r > 200) & (g < 60) & (b < 60)).any() and ((b > 120) & (r < 40) & (g < 40)).any()


def test_python_m_runs_the_same_command_line(tmp_path):
    """``python -m droidw_cli`` is the ``droidw`` command: same errors, same exit codes."""
    import subprocess
    import sys

    missing = tmp_path / "nope.txt"
    proc = subprocess.run([sys.executable, "-m", "droidw_cli", "eval", "--gt", str(missing), "--est", str(missing)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("droidw: error:") and "nope.txt" in proc.stderr
