"""RGB-D mode end to end (``droidw track --depth``), its user errors, and the dynamic exports of a run.

One short 320×240 RGB-D clip with movers is tracked once with scene-consistency
masks; the tests read its run folder.  Accuracy at full length comes from
``benchmarks/dynamic_bench.py --modes``.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cli_run import run
from droidw_cli.eval.dynamic import masks_on_grid
from droidw_cli.io.input import open_source
from droidw_cli.synth import SynthConfig, write_sequence
from droidw_cli.track import depth_config

AREA = 76800  # 240 x 320 working size
SHORT = ["--set", f"io.target_area={AREA}", "--set", "motion_filter.thresh=1.5", "--set", "frontend.keyframe_thresh=1.5"]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    cfg = SynthConfig.preset("dynamic", width=320, height=240, frames=40, seed=1)
    return write_sequence(cfg, tmp_path_factory.mktemp("rgbd") / "seq", progress=False)


@pytest.fixture(scope="module")
def rgbd_run(seq, tmp_path_factory):
    out = tmp_path_factory.mktemp("rgbd_run") / "run"
    from droidw_cli.cli import main

    try:
        main(["track", str(seq), "--depth", "--out", str(out), "--quiet", "--set", "dynamics.mode=consistency", *SHORT])
    except SystemExit as exc:
        assert exc.code in (0, None)
    return out


def test_depth_flag_is_the_rgbd_config():
    assert depth_config("default", (), True) == ("rgbd", ())
    assert depth_config("fast", ("a.b=1",), True) == ("fast", ("io.use_depth=true", "a.b=1"))
    assert depth_config("default", (), False) == ("default", ())


def test_help_shows_the_depth_options(capsys):
    code, out, _ = run(["track", "--help"], capsys)
    assert code == 0 and "--depth" in out and "--depth-scale" in out and "se3" in out


def test_depth_scale_sets_the_metres(seq):
    source = open_source(seq, max_frames=1)
    from droidw_cli.io.rgbd import open_depth

    open_depth(source, 2500.0)
    frame = next(iter(source))
    raw = cv2.imread(str(sorted((seq / "depth").iterdir())[0]), cv2.IMREAD_UNCHANGED)
    np.testing.assert_allclose(frame.depth, raw / 2500.0, rtol=1e-6)


def test_rgbd_run_is_metric_and_records_masks_and_objects(seq, rgbd_run):
    info = json.loads((rgbd_run / "run.json").read_text())
    assert info["metric"] is True and "se3" in info["scale"] and info["config"]["io"]["use_depth"] is True
    assert info["config"]["dynamics"]["mode"] == "consistency"
    with np.load(rgbd_run / "keyframes.npz") as z:
        dynamic, ids, table, index = z["dynamic"], z["object_ids"], z["objects"], z["index"]
    assert dynamic.shape == ids.shape and np.all((ids >= 0) <= dynamic)  # an object pixel is a dynamic pixel
    names = sorted((seq / "mask").iterdir())
    truth = masks_on_grid([names[i] for i in index], (240, 320), AREA)
    precision = (dynamic & truth).sum() / max(1, dynamic.sum())
    assert dynamic.any() and precision > 0.5
    assert table.shape[1] == 8 and set(np.unique(table[:, 1]).astype(int)) == set(np.unique(ids[ids >= 0]))


def test_export_objects_schema(rgbd_run, tmp_path, capsys):
    out = tmp_path / "objects.json"
    code, stdout, _ = run(["export", "objects", str(rgbd_run), "--out", str(out)], capsys)
    assert code == 0 and "objects" in stdout
    doc = json.loads(out.read_text())
    assert doc["schema"] == "droidw-objects/1" and doc["metric"] is True and doc["objects"]
    with np.load(rgbd_run / "keyframes.npz") as z:
        poses = z["poses_c2w"]
    k_src = np.loadtxt(rgbd_run / "calib.txt")[:4]
    for obj in doc["objects"]:
        kfs = obj["keyframes"]
        assert obj["first_frame"] == kfs[0]["frame"] <= obj["last_frame"] == kfs[-1]["frame"]
        assert obj["first_timestamp"] <= obj["last_timestamp"]
        for rec in kfs:
            x, y = rec["centre"]
            assert 0 <= x < 320 and 0 <= y < 240
            if rec["centroid"] is None:
                continue
            # the world centroid, seen from its keyframe, lies in front of the camera and inside the view
            c2w = poses[rec["keyframe"]]
            p = c2w[:3, :3].T @ (np.asarray(rec["centroid"]) - c2w[:3, 3])
            assert p[2] > 0.1
            u, v = k_src[0] * p[0] / p[2] + k_src[2], k_src[1] * p[1] / p[2] + k_src[3]
            assert -20 <= u <= 340 and -20 <= v <= 260


def test_composite_ply(rgbd_run, tmp_path, capsys):
    plyfile = pytest.importorskip("plyfile")
    counts = {}
    for what in ("static", "dynamic", "all"):
        code, _, _ = run(["export", "ply", str(rgbd_run), "--what", what, "--out", str(tmp_path / f"{what}.ply")], capsys)
        assert code == 0
        counts[what] = plyfile.PlyData.read(str(tmp_path / f"{what}.ply"))["vertex"]
    assert counts["static"].count + counts["dynamic"].count == counts["all"].count
    dyn = counts["dynamic"]
    assert {"t", "object_id"} <= {p.name for p in dyn.properties} and dyn.count > 0
    assert np.any(dyn["object_id"] >= 0)
    flags = counts["all"]["dynamic"]
    assert int(flags.sum()) == dyn.count
    with np.load(rgbd_run / "keyframes.npz") as z:
        assert dyn.count == int(z["dynamic"].sum())  # every masked pixel, and none in the static cloud


def test_missized_depth_is_an_error_without_output(seq, tmp_path, capsys):
    bad = tmp_path / "bad"
    import shutil

    shutil.copytree(seq, bad)
    victim = sorted((bad / "depth").iterdir())[5]
    cv2.imwrite(str(victim), np.zeros((100, 100), np.uint16))
    out = tmp_path / "out"
    code, _, err = run(["track", str(bad), "--depth", "--out", str(out), "--quiet", *SHORT], capsys)
    assert code == 2 and "depth image is 100x100" in err and victim.name in err
    assert not out.exists() or not any(p for p in out.iterdir() if not p.name.startswith("."))


def test_depth_needs_depth_images_and_a_positive_scale(seq, tmp_path, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    for p in sorted((seq / "rgb").iterdir())[:5]:
        (folder / p.name).write_bytes(p.read_bytes())
    code, _, err = run(["track", str(folder), "--depth", "--calib", str(seq / "calib.txt"), "--out",
                        str(tmp_path / "o1")], capsys)
    assert code == 2 and "needs depth images" in err
    code, _, err = run(["track", str(seq), "--depth", "--depth-scale", "0", "--out", str(tmp_path / "o2")], capsys)
    assert code == 2 and "--depth-scale" in err
    assert not (tmp_path / "o1").exists() and not (tmp_path / "o2").exists()


def _copy_with(seq, dest, depth_lines=None, zero_depth=False):
    import shutil

    shutil.copytree(seq, dest)
    if zero_depth:
        for p in (dest / "depth").iterdir():
            cv2.imwrite(str(p), np.zeros((240, 320), np.uint16))
    if depth_lines is not None:
        lines = (seq / "depth.txt").read_text().splitlines()
        head = [ln for ln in lines if ln.startswith("#")]
        body = [ln for ln in lines if not ln.startswith("#")]
        (dest / "depth.txt").write_text("\n".join(head + depth_lines(body)) + "\n")
    return dest


def test_depth_without_any_valid_pixel_is_an_error_without_output(seq, tmp_path, capsys):
    bad = _copy_with(seq, tmp_path / "zero", zero_depth=True)
    out = tmp_path / "out"
    code, _, err = run(["track", str(bad), "--depth", "--out", str(out), "--quiet", *SHORT], capsys)
    assert code == 2 and "hold no depth" in err and not out.exists()


def test_depth_listing_that_pairs_no_frame_is_an_error(seq, tmp_path, capsys):
    shifted = _copy_with(seq, tmp_path / "shifted",
                         lambda body: [f"{float(t) + 100:.6f} {name}" for t, name in (ln.split() for ln in body)])
    out = tmp_path / "out"
    code, _, err = run(["track", str(shifted), "--depth", "--out", str(out), "--quiet", *SHORT], capsys)
    assert code == 2 and "none of the 40 selected frames has a depth image" in err and not out.exists()


def test_frames_without_a_depth_image_are_counted_in_a_warning(seq, tmp_path):
    from droidw_cli.io.rgbd import open_depth

    half = _copy_with(seq, tmp_path / "half", lambda body: body[::2])
    source = open_source(half)
    notes = open_depth(source, 5000.0)
    assert len(notes) == 1 and "20 of the 40 selected frames have no depth image" in notes[0]
    assert sum(f.depth is None for f in source) == 20


def test_a_depth_scale_that_gives_implausible_depth_is_a_warning(seq):
    from droidw_cli.io.rgbd import open_depth

    assert open_depth(open_source(seq), 5000.0) == []  # the generator's room: metres of depth
    for scale in (50.0, 5e5):  # 100× too far, 100× too near
        notes = open_depth(open_source(seq), scale)
        assert len(notes) == 1 and "check --depth-scale" in notes[0] and f"--depth-scale {scale:g}" in notes[0]


def test_export_objects_of_a_run_without_masks_is_an_error(seq, tmp_path, capsys):
    out = tmp_path / "plain"
    code, _, _ = run(["track", str(seq), "--out", str(out), "--quiet", "--max-frames", "12",
                      "--set", "dynamics.mode=none", *SHORT], capsys)
    assert code == 0
    code, _, err = run(["export", "objects", str(out), "--out", str(tmp_path / "o.json")], capsys)
    assert code == 2 and "dynamics.mode=none" in err and not (tmp_path / "o.json").exists()


def test_lazy_depth_reads_the_same_depth_and_checks_sizes_from_the_header(seq, tmp_path):
    """RGB-D tracking decodes keyframes' depth only (LazyDepth); calling one gives the eager read."""
    import shutil
    import warnings

    from droidw_cli.errors import InputError
    from droidw_cli.io.frames import LazyDepth, png_size

    eager = open_source(seq)
    lazy = open_source(seq)
    lazy.lazy_depth = True
    for a, b in zip(eager, lazy):
        assert isinstance(b.depth, LazyDepth)
        np.testing.assert_array_equal(b.depth(), a.depth)
    first = sorted((seq / "depth").iterdir())[0]
    assert png_size(first) == (240, 320) and png_size(seq / "calib.txt") is None

    bad = tmp_path / "bad"
    shutil.copytree(seq, bad)
    victim = sorted((bad / "depth").iterdir())[5]
    cv2.imwrite(str(victim), np.zeros((100, 100), np.uint16))
    source = open_source(bad)
    source.lazy_depth = True
    frames = list(source)  # not strict: the mis-sized depth is found when it is read
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert frames[5].depth() is None
    assert any(victim.name in str(w.message) for w in caught)
    source.strict_depth = True
    with pytest.raises(InputError, match="depth image is 100x100"):
        list(source)  # strict: the header is enough, no decoding
