"""``droidw view --save``: a run logged to an .rrd file headless, and read back by rerun."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from cli_run import run
from tiny_runs import track_tiny_clip


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A real `droidw track` run of a short synthetic clip (one torch thread: a few seconds)."""
    return track_tiny_clip(tmp_path_factory.mktemp("view"), 20)


def entity_rows(path: Path) -> dict[str, int] | None:
    """Entity path -> logged rows, read back with rerun's own reader (None if this rerun has none)."""
    try:
        from rerun.chunk import RrdReader
    except ImportError:
        return None
    rows: dict[str, int] = {}
    for chunk in RrdReader(path).stream():
        rows[str(chunk.entity_path)] = rows.get(str(chunk.entity_path), 0) + chunk.num_rows
    return rows


def test_save_writes_an_rrd_that_rerun_reads_back(run_dir, tmp_path, capsys):
    pytest.importorskip("rerun")
    import numpy as np

    rrd = tmp_path / "out" / "run.rrd"
    code, out, err = run(["view", str(run_dir), "--save", str(rrd), "--quiet"], capsys)
    assert code == 0, err
    assert rrd.is_file() and rrd.stat().st_size > 10_000
    assert sorted(p.name for p in rrd.parent.iterdir()) == ["run.rrd"]  # no temporary file left
    assert f"wrote {rrd}" in out
    with np.load(run_dir / "keyframes.npz") as z:
        n_kf = len(z["index"])
    n_frames = sum(1 for line in (run_dir / "traj.txt").read_text().splitlines() if line and line[0] != "#")
    rows = entity_rows(rrd)
    if rows is None:  # an older rerun: its command line checks the file instead
        cli = Path(sys.executable).parent / "rerun"
        if not cli.is_file():
            pytest.skip("this rerun has neither rerun.chunk.RrdReader nor the rerun command")
        proc = subprocess.run([str(cli), "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
        assert proc.returncode == 0, proc.stderr
        return
    for entity in ("/world/trajectory", "/world/keyframes", "/world/points/static", "/world/points/dynamic",
                   "/world/camera", "/world/camera/image", "/uncertainty", "/run"):
        assert entity in rows, entity
    assert rows["/world/camera"] == n_frames  # a pose at every frame
    assert rows["/uncertainty"] == n_kf  # an overlay at every keyframe
    assert rows["/world/camera/image"] == n_kf + 1  # the pinhole (static) and one image per keyframe


def test_view_errors(run_dir, tmp_path, capsys, monkeypatch):
    pytest.importorskip("rerun")
    code, _, err = run(["view", str(tmp_path / "nothing"), "--save", str(tmp_path / "x.rrd")], capsys)
    assert code == 2 and "not a run folder" in err
    if sys.platform.startswith("linux"):  # no display: say how to save instead
        monkeypatch.delenv("DISPLAY", raising=False)
        monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
        code, _, err = run(["view", str(run_dir)], capsys)
        assert code == 2 and "--save" in err
    monkeypatch.setitem(sys.modules, "rerun", None)  # as if the extra were not installed
    code, _, err = run(["view", str(run_dir), "--save", str(tmp_path / "x.rrd")], capsys)
    assert code == 2 and "pip install 'droidw[view]'" in err
    assert not (tmp_path / "x.rrd").exists()


def test_view_of_a_single_keyframe_run_shows_it_without_a_cloud(tmp_path, capsys):
    """One keyframe (a fixed camera): no multi-view map, so no points, but the trajectory and images, and a
    warning that says why (it used to crash)."""
    pytest.importorskip("rerun")
    import numpy as np

    from droidw_cli.geometry.camera import BA_SCALE, unscale_intrinsics

    h, w = 12, 16
    folder = tmp_path / "run"
    folder.mkdir()
    np.savez(folder / "keyframes.npz", index=np.array([0]), timestamps=np.array([0.0]), poses_c2w=np.eye(4)[None],
             disps=np.ones((1, h, w), np.float32), work_size=np.array([h * BA_SCALE, w * BA_SCALE]),
             intrinsics=unscale_intrinsics(np.array([12.0, 12.0, (w - 1) / 2, (h - 1) / 2]), BA_SCALE),
             images=np.full((1, 2 * h, 2 * w, 3), 128, np.uint8), uncertainty=np.full((1, h, w), 0.7, np.float32))
    rrd = tmp_path / "out" / "run.rrd"
    code, out, err = run(["view", str(folder), "--save", str(rrd), "--quiet"], capsys)
    assert code == 0, err
    assert "warning: no point cloud: the run has 1 keyframe" in err and "--min-views" not in err
    assert "1 keyframes, 0 static and 0 dynamic points" in out
    assert rrd.is_file() and rrd.stat().st_size > 0
