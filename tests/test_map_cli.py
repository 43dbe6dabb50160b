"""``droidw map`` end to end on a short synthetic run, and its one-line errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from cli_run import run
from tiny_runs import track_tiny_clip

#: measured on this tiny run (80×60 map, 40 steps): static-pixel PSNR of the held-out frames 17.98 dB with the
#: least-median-of-squares epipolar masks, 15.22 dB with RANSAC and refits (2026-11-28: the run masks 31.5 % of
#: its keyframe cells instead of 27.1 %, so fewer static Gaussians cover the held-out frames; all pixels 17.54
#: against 17.44 dB, the run's ATE 7.4 against 7.6 cm); 14.09 dB with keyframe placement (slam/placement.py; this
#: 24-frame run's ATE 7.44 → 7.93 cm).  The run, not the map, is what moves this figure
PSNR_BOUND = 13.5


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A real `droidw track` run of a short synthetic clip with walkers (one torch thread: seconds)."""
    return track_tiny_clip(tmp_path_factory.mktemp("map"), 24)


@pytest.fixture(scope="module")
def mapped(run_dir, tmp_path_factory):
    import torch

    out = tmp_path_factory.mktemp("mapped") / "map"
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        from droidw_cli.cli import main

        try:
            main([ "map", str(run_dir), "--out", str(out), "--steps", "40", "--object-steps", "3",
                  "--holdout-every", "3", "--quiet"])
        except SystemExit as exc:
            assert exc.code in (0, None)
    finally:
        torch.set_num_threads(before)
    return out


def test_map_writes_every_output(mapped):
    import plyfile

    assert sorted(p.name for p in mapped.iterdir()) == ["dynamic.ply", "map.json", "static.ply", "views"]
    doc = json.loads((mapped / "map.json").read_text())
    assert doc["schema"] == "droidw-map/1" and doc["static"]["ended"] == "steps" and doc["static"]["steps"] == 40
    static = plyfile.PlyData.read(str(mapped / "static.ply"))["vertex"]
    assert static.count == doc["gaussians"]["static"] > 100
    dyn = plyfile.PlyData.read(str(mapped / "dynamic.ply"))["vertex"]
    assert dyn.count == doc["gaussians"]["dynamic"]
    views = sorted((mapped / "views").glob("frame_*.png"))
    assert len(views) == doc["heldout"]["frames"] >= 1
    assert doc["heldout"]["mask_source"] == "input"  # the generator's ground-truth masks


def test_held_out_psnr_is_above_the_measured_bound(mapped):
    doc = json.loads((mapped / "map.json").read_text())
    psnr = doc["heldout"]["mean"]["psnr_static_pixels"]
    assert psnr > PSNR_BOUND, psnr


def test_map_is_deterministic_when_the_steps_end_it(run_dir, tmp_path, capsys, mapped):
    code, out, err = run(["map", str(run_dir), "--out", str(tmp_path / "again"), "--steps", "40",
                          "--object-steps", "3", "--holdout-every", "3", "--quiet"], capsys)
    assert code == 0, err
    assert (tmp_path / "again" / "static.ply").read_bytes() == (mapped / "static.ply").read_bytes()


def _nothing_written(parent: Path, name: str) -> bool:
    return not (parent / name).exists() and not any(p.name.startswith(".droidw-map-") for p in parent.iterdir())


def test_missing_run_folder_is_one_line_and_exit_2(tmp_path, capsys):
    code, _, err = run(["map", str(tmp_path / "nope"), "--out", str(tmp_path / "m")], capsys)
    assert code == 2 and err.count("\n") == 1 and "no such run folder" in err
    assert _nothing_written(tmp_path, "m")


def test_fixed_camera_run_has_no_map(run_dir, tmp_path, capsys):
    fixed = tmp_path / "fixed"
    shutil.copytree(run_dir, fixed)
    with np.load(fixed / "keyframes.npz") as z:
        arrays = {k: z[k] for k in z.files}
    arrays["poses_c2w"] = np.repeat(arrays["poses_c2w"][:1], len(arrays["poses_c2w"]), axis=0)
    np.savez(fixed / "keyframes.npz", **arrays)
    code, _, err = run(["map", str(fixed), "--out", str(tmp_path / "m")], capsys)
    assert code == 2 and err.count("\n") == 1 and "camera never moved" in err
    assert _nothing_written(tmp_path, "m")


def test_budget_too_small_is_one_line_and_exit_2(run_dir, tmp_path, capsys):
    code, _, err = run(["map", str(run_dir), "--out", str(tmp_path / "m"), "--minutes", "0.01"], capsys)
    assert code == 2 and err.count("\n") == 1 and "too short" in err
    assert _nothing_written(tmp_path, "m")


def test_bad_size_is_one_line(run_dir, tmp_path, capsys):
    code, _, err = run(["map", str(run_dir), "--out", str(tmp_path / "m"), "--size", "100x20"], capsys)
    assert code == 2 and "aspect ratio" in err
    assert _nothing_written(tmp_path, "m")


def test_view_shows_the_map_as_ellipsoids(run_dir, mapped, tmp_path, capsys):
    pytest.importorskip("rerun")
    from test_view import entity_rows

    code, out, err = run(["view", str(run_dir), "--map", str(mapped), "--save", str(tmp_path / "m.rrd"), "--quiet"],
                         capsys)
    assert code == 0, err
    doc = json.loads((mapped / "map.json").read_text())
    assert f"{doc['gaussians']['static'] + doc['gaussians']['dynamic']} Gaussians" in out
    rows = entity_rows(tmp_path / "m.rrd")
    if rows is not None:
        assert "/world/gaussians/static" in rows or "world/gaussians/static" in rows
    code, _, err = run(["view", str(run_dir), "--map", str(tmp_path), "--save", str(tmp_path / "n.rrd")], capsys)
    assert code == 2 and "no static.ply" in err
