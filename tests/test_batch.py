"""``droidw batch``: manifests, summaries, in-order runs, Ray runs, re-runs and interruptions."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import pytest

from droidw_cli.batch.manifest import ManifestError, load_manifest
from droidw_cli.batch.summary import format_markdown, mean_row
from cli_run import run

# small, quick clips: 160x120, 20 frames at 10 fps (enough motion for a few keyframes)
TRACK_SET = {"io.target_area": 19200, "motion_filter.thresh": 1.0, "frontend.keyframe_thresh": 1.0}


@pytest.fixture(scope="module")
def clips(tmp_path_factory) -> Path:
    """Two synthetic sequences with ground truth and a corrupt 'video'."""
    from droidw_cli.synth import SynthConfig, write_sequence

    root = tmp_path_factory.mktemp("clips")
    for seed in (1, 2):
        cfg = SynthConfig.preset("dynamic", seed=seed, frames=20, width=160, height=120, fps=10.0)
        write_sequence(cfg, root / f"seq{seed}", video=False, progress=False)
    (root / "broken.mp4").write_bytes(b"this is not a video\x00\x01\x02" * 10)
    return root


def write_manifest(clips: Path, rows: list[dict], name: str = "manifest.yaml") -> Path:
    import yaml

    path = clips / name
    path.write_text(yaml.safe_dump({"defaults": {"config": "fast", "set": TRACK_SET}, "sequences": rows}))
    return path


THREE_ROWS = [{"input": "seq1", "gt": "seq1/groundtruth.txt"},
              {"input": "seq2", "gt": "seq2/groundtruth.txt", "align": "se3"},
              {"input": "broken.mp4"}]


def read_summary(out: Path) -> dict[str, dict]:
    with open(out / "summary.csv", newline="") as fh:
        return {r["name"]: r for r in csv.DictReader(fh)}


# ---------------------------------------------------------------- manifests

def test_yaml_manifest_defaults_overrides_and_paths(tmp_path):
    (tmp_path / "m.yaml").write_text(
        "defaults:\n  config: fast\n  set: {frontend.window: 12}\n"
        "sequences:\n"
        "  - input: videos/a.mp4\n    calib: auto\n    set: [uncertainty.enable=false]\n"
        "  - {input: /abs/tum_walk/, gt: gt.txt, align: SE3, backend.iters: 3, config: my.yaml}\n"
        "  - {input: other/a.mp4}\n")
    rows = load_manifest(tmp_path / "m.yaml")
    assert [r.name for r in rows] == ["a", "tum_walk", "a-2"]
    a, tum, _ = rows
    assert a.input == str(tmp_path / "videos/a.mp4") and a.calib == "auto" and a.config == "fast"
    assert a.overrides == ("frontend.window=12", "uncertainty.enable=false")
    assert tum.input == "/abs/tum_walk" and tum.gt == str(tmp_path / "gt.txt") and tum.align == "se3"
    assert tum.config == str(tmp_path / "my.yaml")
    assert tum.overrides == ("frontend.window=12", "backend.iters=3")


def test_csv_manifest_with_set_and_override_columns(tmp_path):
    (tmp_path / "m.csv").write_text(
        "# comment line\nname,input,gt,set,frontend.window\n"
        "one,seq1,seq1/groundtruth.txt,uncertainty.enable=false; backend.iters=2,30\n"
        ",seq2,,,\n")
    one, two = load_manifest(tmp_path / "m.csv")
    assert one.name == "one" and one.gt == str(tmp_path / "seq1/groundtruth.txt")
    assert one.overrides == ("uncertainty.enable=false", "backend.iters=2", "frontend.window=30")
    assert two.name == "seq2" and two.gt is None and two.overrides == () and two.config is None


def test_depth_columns_and_the_align_default(tmp_path):
    (tmp_path / "m.csv").write_text("input,gt,depth,depth_scale,align\n"
                                    "a,a/gt.txt,yes,1000,\nb,b/gt.txt,,,SIM3\nc,,False,,\n")
    a, b, c = load_manifest(tmp_path / "m.csv")
    assert a.depth and a.depth_scale == 1000.0 and a.align is None  # se3 or sim3 once the run says metric or not
    assert not b.depth and b.depth_scale == 5000.0 and b.align == "sim3"
    assert not c.depth


@pytest.mark.parametrize("text,message", [
    ("- {input: a.mp4, depth: maybe}\n", "depth must be true or false"),
    ("- {input: a.mp4, depth: true, depth_scale: 0}\n", "depth_scale must be a positive number"),
    ("- {input: a.mp4, depth_scale: deep}\n", "depth_scale must be a positive number"),
    ("- {input: a.mp4, colour: red}\n", "unknown column(s) colour"),
    ("- {gt: g.txt}\n", "'input' is required"),
    ("- {input: a.mp4, name: x}\n- {input: b.mp4, name: x}\n", "given to more than one row"),
    ("- {input: a.mp4, align: affine}\n", "align must be one of"),
    ("- {input: a.mp4, name: ../up}\n", "must be letters"),
    ("- {input: a.mp4, set: [nokey]}\n", "not KEY=VALUE"),
    ("[]\n", "no rows"),
    ("sequences: [{input: a]\n", "not valid YAML"),
])
def test_manifest_errors_name_the_row(tmp_path, text, message):
    (tmp_path / "m.yaml").write_text(text)
    with pytest.raises(ManifestError, match=message.replace("(", r"\(").replace(")", r"\)")):
        load_manifest(tmp_path / "m.yaml")


def test_summary_mean_row_and_markdown():
    recs = [{"name": "a", "status": "ok", "ate_rmse_m": 0.02, "fps": 4.0, "keyframes": 10, "frames": 100},
            {"name": "b", "status": "ok", "ate_rmse_m": 0.04, "fps": 2.0, "keyframes": 20, "frames": 100,
             "reused": True},
            {"name": "c", "status": "failed", "error": "c.mp4: cannot open | the video"}]
    m = mean_row(recs)
    assert m["status"] == "2/3 ok" and m["ate_rmse_m"] == pytest.approx(0.03) and m["keyframes"] == 15
    md = format_markdown(recs)
    assert "| **mean** | 2/3 ok | 3.00 |" in md and "ok (reused)" in md and "cannot open \\| the video" in md


# ---------------------------------------------------------------- runs

def test_in_order_without_ray_skips_finished_and_cleans_partials(clips, tmp_path, capsys, monkeypatch):
    import torch

    monkeypatch.setitem(sys.modules, "ray", None)  # as if Ray were not installed
    manifest = write_manifest(clips, [THREE_ROWS[0], THREE_ROWS[2]], "two.yaml")
    out = tmp_path / "out"
    (out / ".seq1.partial-deadbeef").mkdir(parents=True)  # left by a killed run
    threads = torch.get_num_threads()
    code, stdout, err = run(["batch", str(manifest), "--out", str(out), "--quiet"], capsys)
    assert code == 1, err  # one sequence failed
    assert torch.get_num_threads() == threads
    assert sorted(p.name for p in out.iterdir()) == ["broken", "seq1", "summary.csv", "summary.md"]
    rows = read_summary(out)
    assert rows["seq1"]["status"] == "ok" and float(rows["seq1"]["ate_rmse_m"]) > 0
    assert rows["broken"]["status"] == "failed" and "cannot open" in rows["broken"]["error"]
    assert {"traj.txt", "keyframes.npz", "run.json", "calib.txt", "eval.json", "ate.zip", "status.json"} <= {
        p.name for p in (out / "seq1").iterdir()}
    assert "1 of 2 sequences ok" in stdout
    # a re-run skips the finished sequence, retries the failed one; --force runs both
    stamp = (out / "seq1" / "status.json").stat().st_mtime_ns
    code, stdout, _ = run(["batch", str(manifest), "--out", str(out), "--workers", "1", "--quiet"], capsys)
    assert code == 1 and "1 finished earlier, skipped" in stdout
    assert (out / "seq1" / "status.json").stat().st_mtime_ns == stamp
    assert read_summary(out)["seq1"]["reused"] == "yes"
    # anything that needs Ray says how to install it
    code, _, err = run(["batch", str(manifest), "--out", str(out), "--workers", "2"], capsys)
    assert code == 2 and "pip install 'droidw[ray]'" in err and "\n" not in err.strip()


def test_an_rgbd_row_is_metric_and_evaluated_in_se3(clips, tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    manifest = write_manifest(clips, [{"name": "rgbd", "input": "seq1", "gt": "seq1/groundtruth.txt", "depth": True},
                                      {"name": "mono", "input": "seq1", "gt": "seq1/groundtruth.txt"}], "rgbd.yaml")
    out = tmp_path / "out"
    code, _, err = run(["batch", str(manifest), "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    for name, metric, align in (("rgbd", True, "se3"), ("mono", False, "sim3")):
        assert json.loads((out / name / "run.json").read_text())["metric"] is metric
        assert json.loads((out / name / "eval.json").read_text())["align"] == align
        assert json.loads((out / name / "status.json").read_text())["align"] == align


def test_interrupt_leaves_no_half_written_sequence(clips, tmp_path, monkeypatch):
    from droidw_cli.batch import BatchOptions, load_manifest, run_batch
    from droidw_cli import track

    def fake_track(input_path, out_dir, *args, **kwargs):
        (Path(out_dir) / "traj.txt").write_text("half\n")
        raise KeyboardInterrupt

    monkeypatch.setattr(track, "run_track", fake_track)
    out = tmp_path / "out"
    with pytest.raises(KeyboardInterrupt):
        run_batch(load_manifest(write_manifest(clips, THREE_ROWS[:2], "int.yaml")), BatchOptions(out=out))
    assert sorted(p.name for p in out.iterdir()) == ["summary.csv", "summary.md"]
    assert {r["status"] for r in read_summary(out).values()} == {"cancelled", "0/2 ok"}


@pytest.mark.slow
def test_three_rows_on_a_local_ray_runtime_with_two_workers(clips, tmp_path, capsys):
    pytest.importorskip("ray")
    manifest = write_manifest(clips, THREE_ROWS)
    out = tmp_path / "out"
    code, stdout, err = run(["batch", str(manifest), "--out", str(out), "--workers", "2", "--quiet"], capsys)
    assert code == 1, err
    rows = read_summary(out)
    assert [rows[n]["status"] for n in ("seq1", "seq2", "broken")] == ["ok", "ok", "failed"]
    assert "cannot open the video" in rows["broken"]["error"]
    assert rows["mean"]["status"] == "2/3 ok"
    for name in ("seq1", "seq2"):
        status = json.loads((out / name / "status.json").read_text())
        assert status["threads"] == 1 and status["keyframes"] >= 2 and status["ate_rmse_m"] > 0
        assert float(rows[name]["ate_rmse_m"]) == pytest.approx(status["ate_rmse_m"], rel=1e-5)
    assert json.loads((out / "seq2" / "eval.json").read_text())["align"] == "se3"
    assert not [p for p in out.iterdir() if p.name.startswith(".")]
    assert "2 of 3 sequences ok" in stdout
