"""Synthetic sequence folders: TUM layout, exact encodings, byte determinism, video, the CLI."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from droidw_cli.errors import UserError
from droidw_cli.io.trajectory import read_trajectory
from droidw_cli.synth import SynthConfig, render_sequence, write_sequence

CFG = SynthConfig.preset("dynamic-small", seed=5, width=96, height=72, frames=6)


def _list(path: Path) -> list[tuple[float, str]]:
    rows = []
    for line in path.read_text().splitlines():
        if line.startswith("#") or not line.strip():
            continue
        t, name = line.split()
        rows.append((float(t), name))
    return rows


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> Path:
    return write_sequence(CFG, tmp_path_factory.mktemp("synth") / "seq", progress=False)


def test_folder_layout_and_contents(written):
    frames = list(render_sequence(CFG))
    assert sorted(p.name for p in written.iterdir()) == sorted(
        ["rgb", "depth", "mask", "rgb.txt", "depth.txt", "mask.txt", "groundtruth.txt", "calib.txt", "synth.json"])
    assert not list(written.parent.glob(".seq.*"))  # temp folder renamed away
    for kind in ("rgb", "depth", "mask"):
        rows = _list(written / f"{kind}.txt")
        assert [t for t, _ in rows] == pytest.approx([f.timestamp for f in frames])
        assert [n for _, n in rows] == [f"{kind}/{f.timestamp:.6f}.png" for f in frames]
        assert all((written / n).is_file() for _, n in rows)
    for f in frames:
        name = f"{f.timestamp:.6f}.png"
        rgb = cv2.imread(str(written / "rgb" / name), cv2.IMREAD_UNCHANGED)
        assert np.array_equal(rgb[..., ::-1], f.rgb)
        depth = cv2.imread(str(written / "depth" / name), cv2.IMREAD_UNCHANGED)
        assert depth.dtype == np.uint16
        assert np.abs(depth / 5000.0 - f.depth).max() <= 0.5 / 5000 + 1e-6
        mask = cv2.imread(str(written / "mask" / name), cv2.IMREAD_UNCHANGED)
        assert mask.dtype == np.uint8 and set(np.unique(mask)) <= {0, 255}
        assert np.array_equal(mask == 255, f.mask)
    traj = read_trajectory(written / "groundtruth.txt")
    assert len(traj) == CFG.frames
    np.testing.assert_allclose(traj.timestamps, [f.timestamp for f in frames], atol=1e-6)
    np.testing.assert_allclose(traj.poses, np.stack([f.pose_c2w for f in frames]), atol=1e-6)
    calib = [float(v) for v in (written / "calib.txt").read_text().split()]
    np.testing.assert_allclose(calib, CFG.intrinsics, atol=1e-5)


def test_same_seed_gives_byte_identical_files(written, tmp_path):
    again = write_sequence(CFG, tmp_path / "again", progress=False)
    for kind in ("rgb", "depth", "mask"):
        names = sorted(p.name for p in (written / kind).iterdir())
        assert names == sorted(p.name for p in (again / kind).iterdir())
        for n in names:
            assert (written / kind / n).read_bytes() == (again / kind / n).read_bytes()
    assert (written / "groundtruth.txt").read_bytes() == (again / "groundtruth.txt").read_bytes()
    other = write_sequence(CFG.replace(seed=6), tmp_path / "other", progress=False)
    first = sorted((other / "rgb").iterdir())[0]
    assert first.read_bytes() != (written / "rgb" / first.name).read_bytes()


def test_existing_folder_needs_overwrite(tmp_path):
    cfg = CFG.replace(frames=2)
    out = tmp_path / "seq"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    with pytest.raises(UserError, match="not empty"):
        write_sequence(cfg, out, progress=False)
    assert (out / "keep.txt").is_file()
    write_sequence(cfg, out, progress=False, overwrite=True)
    assert not (out / "keep.txt").exists() and len(_list(out / "rgb.txt")) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["seq"]  # no temp or old folders left
    (tmp_path / "file").write_text("x")
    with pytest.raises(UserError, match="not a folder"):
        write_sequence(cfg, tmp_path / "file", progress=False)


def test_video_is_written(tmp_path):
    cfg = CFG.replace(frames=4)
    out = write_sequence(cfg, tmp_path / "vid", video=True, progress=False)
    videos = list(out.glob("video.*"))
    assert len(videos) == 1
    cap = cv2.VideoCapture(str(videos[0]))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == cfg.frames


def test_cli_synth_writes_a_folder(tmp_path, capsys):
    from droidw_cli.cli import main

    out = tmp_path / "cli"
    main(["synth", str(out), "--preset", "dynamic-small", "--frames", "3", "--size", "80x60", "--seed", "2",
          "--movers", "2"])
    assert "wrote 3 frames" in capsys.readouterr().out
    assert len(_list(out / "rgb.txt")) == 3
    img = cv2.imread(str(sorted((out / "rgb").iterdir())[0]))
    assert img.shape == (60, 80, 3)
    assert len(read_trajectory(out / "groundtruth.txt")) == 3

    main(["synth", str(tmp_path / "st"), "--static", "--frames", "2", "--size", "64x48", "--quiet"])
    masks = sorted((tmp_path / "st" / "mask").iterdir())
    assert all(cv2.imread(str(m), cv2.IMREAD_UNCHANGED).max() == 0 for m in masks)

    with pytest.raises(SystemExit) as exc:
        main(["synth", str(out), "--frames", "2", "--size", "64x48", "--quiet"])  # exists, no --overwrite
    assert exc.value.code == 2
    assert "not empty" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["synth", str(tmp_path / "bad"), "--size", "640by480"])
    assert exc.value.code == 2
    assert not (tmp_path / "bad").exists()
