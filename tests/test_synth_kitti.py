"""The generator's KITTI layout, and synth → track → eval on it with no --calib."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from cli_run import run
from droidw_cli.errors import UserError
from droidw_cli.io.calibration import load_calibration
from droidw_cli.io.trajectory import read_kitti, read_trajectory
from droidw_cli.synth import SynthConfig, render_sequence, write_sequence
from droidw_cli.synth.writer import KITTI_BASELINE

CFG = SynthConfig.preset("dynamic-small", seed=5, width=96, height=72, frames=5)


def matrices(path: Path) -> dict[str, np.ndarray]:
    rows = (line.split(":") for line in path.read_text().splitlines())
    return {name: np.array([float(v) for v in values.split()]).reshape(3, 4) for name, values in rows}


@pytest.fixture(scope="module")
def colour_seq(tmp_path_factory) -> Path:
    return write_sequence(CFG, tmp_path_factory.mktemp("kitti") / "seq", progress=False, layout="kitti")


def test_kitti_layout_files(colour_seq):
    frames = list(render_sequence(CFG))
    assert sorted(p.name for p in colour_seq.iterdir()) == sorted(
        ["image_2", "depth", "mask", "times.txt", "calib.txt", "poses.txt", "synth.json"])
    assert not list(colour_seq.parent.glob(".seq.*"))  # temp folder renamed away
    names = [f"{k:06d}.png" for k in range(CFG.frames)]
    for sub in ("image_2", "depth", "mask"):
        assert sorted(p.name for p in (colour_seq / sub).iterdir()) == names
    for f, name in zip(frames, names):
        assert np.array_equal(cv2.imread(str(colour_seq / "image_2" / name), cv2.IMREAD_UNCHANGED)[..., ::-1], f.rgb)
        depth = cv2.imread(str(colour_seq / "depth" / name), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16 and np.abs(depth / CFG.depth_scale - f.depth).max() <= 0.5 / 5000 + 1e-6
        assert np.array_equal(cv2.imread(str(colour_seq / "mask" / name), cv2.IMREAD_UNCHANGED) == 255, f.mask)
    times = np.loadtxt(colour_seq / "times.txt")
    assert times.tolist() == [CFG.timestamp(k) for k in range(CFG.frames)]
    # KITTI poses: camera-to-world of the left camera relative to the first frame
    poses = read_kitti(colour_seq / "poses.txt").poses
    c2w = np.stack([f.pose_c2w for f in frames])
    np.testing.assert_array_equal(poses[0], np.eye(4))
    np.testing.assert_allclose(poses, np.linalg.inv(c2w[0]) @ c2w, atol=1e-8)
    p = matrices(colour_seq / "calib.txt")
    assert list(p) == ["P0", "P1", "P2", "P3", "Tr"]
    np.testing.assert_allclose(p["P0"][:, :3], CFG.K, rtol=1e-12)
    np.testing.assert_array_equal(p["P0"], p["P2"])
    np.testing.assert_array_equal(p["P1"], p["P3"])
    assert p["P1"][0, 3] == pytest.approx(-CFG.K[0, 0] * KITTI_BASELINE) and not p["P1"][1:, 3].any()
    assert load_calibration(colour_seq / "calib.txt", (CFG.height, CFG.width), camera=2).as_array() == \
        pytest.approx(CFG.intrinsics)
    meta = json.loads((colour_seq / "synth.json").read_text())
    assert meta["layout"] == "kitti" and meta["config"]["frames"] == CFG.frames


def test_grey_kitti_layout_writes_single_channel_image_0(tmp_path):
    cfg = CFG.replace(grey=True, frames=2)
    seq = write_sequence(cfg, tmp_path / "grey", progress=False, layout="kitti")
    assert (seq / "image_0").is_dir() and not (seq / "image_2").exists()
    for f in render_sequence(cfg):
        img = cv2.imread(str(seq / "image_0" / f"{f.index:06d}.png"), cv2.IMREAD_UNCHANGED)
        assert img.shape == (cfg.height, cfg.width) and img.dtype == np.uint8
        assert np.array_equal(img, f.rgb[..., 0])


def test_unknown_layout(tmp_path):
    with pytest.raises(UserError, match="unknown layout 'euroc'"):
        write_sequence(CFG, tmp_path / "x", progress=False, layout="euroc")
    assert not (tmp_path / "x").exists()


def test_synth_track_eval_round_trip_without_calib(tmp_path, capsys):
    seq, out = tmp_path / "seq", tmp_path / "run"
    code, _, err = run(["synth", str(seq), "--preset", "static-small", "--frames", "30", "--seed", "2",
                        "--layout", "kitti", "--grey", "--quiet"], capsys)
    assert code == 0, err
    assert (seq / "image_0").is_dir() and not (seq / "rgb.txt").exists()
    cfg = SynthConfig.preset("static-small", frames=30, seed=2, grey=True)
    code, _, err = run(["track", str(seq), "--out", str(out), "--quiet", "--backend", "cpu",
                        "--set", "io.target_area=76800", "--set", "uncertainty.enable=false"], capsys)
    assert code == 0, err
    assert [float(v) for v in (out / "calib.txt").read_text().split()] == pytest.approx(cfg.intrinsics, rel=1e-12)
    info = json.loads((out / "run.json").read_text())
    assert info["calibration"]["source"] == "input"
    traj = read_trajectory(out / "traj.txt")
    np.testing.assert_allclose(traj.timestamps, np.loadtxt(seq / "times.txt"), atol=1e-6)
    # eval takes the KITTI ground truth's times from times.txt beside it
    code, text, err = run(["eval", "--gt", str(seq / "poses.txt"), "--est", str(out), "--json"], capsys)
    assert code == 0, err
    result = json.loads(text)
    assert result["association"] == "timestamp" and result["matches"] == 30
    assert result["ate"]["rmse"] < 0.05  # a sanity bound on this 30-frame clip, not an accuracy figure
    (seq / "times.txt").write_text("0.0\n0.1\n")
    code, _, err = run(["eval", "--gt", str(seq / "poses.txt"), "--est", str(out)], capsys)
    assert code == 2 and "times.txt: 2 timestamps for 30 poses" in err and "--gt-times" in err
