"""``--calib`` wins over a calibration found in the input; an unreadable one there warns, or fails without --calib."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from cli_run import run
from droidw_cli.errors import InputError
from droidw_cli.io.calibration import load_calibration
from droidw_cli.io.input import open_source
from droidw_cli.synth import SynthConfig, write_sequence

CFG = SynthConfig.preset("static-small", seed=3, width=96, height=72, frames=6)
GIVEN = "80.5 81.5 47.0 35.0\n"
# a KITTI calib.txt: the format the old reader rejected with "expected one line ..., got 2 lines"
KITTI_TWO_CAMERAS = ("P0: 70 0 47.5 0 0 70 35.5 0 0 0 1 0\n"
                     "P2: 90 0 48 4.5 0 91 36 -0.1 0 0 1 0.003\n")
FAST = ["--quiet", "--backend", "cpu", "--set", "uncertainty.enable=false"]


@pytest.fixture(scope="module")
def seq(tmp_path_factory):
    return write_sequence(CFG, tmp_path_factory.mktemp("prec") / "seq", progress=False)


@pytest.fixture
def foreign(seq, tmp_path):
    """The sequence with a calib.txt droidw cannot read, and a good calibration file beside it."""
    folder = tmp_path / "seq"
    shutil.copytree(seq, folder)
    (folder / "calib.txt").write_text("fx fy cx cy\n500 500 320 240\n")
    (tmp_path / "given.txt").write_text(GIVEN)
    return folder


def run_calib(out) -> list[float]:
    return [float(v) for v in (out / "calib.txt").read_text().split()]


@pytest.mark.parametrize("calib", ["given", "auto"])
def test_calib_option_wins_over_an_unreadable_input_calibration(foreign, tmp_path, capsys, calib):
    out = tmp_path / "run"
    arg = str(tmp_path / "given.txt") if calib == "given" else "auto"
    code, _, err = run(["track", str(foreign), "--out", str(out), "--calib", arg, *FAST], capsys)
    assert code == 0, err
    assert "warning: ignored the input's calibration" in err and str(foreign / "calib.txt") in err
    info = json.loads((out / "run.json").read_text())
    assert any("ignored the input's calibration" in w and str(foreign / "calib.txt") in w for w in info["warnings"])
    if calib == "given":
        assert run_calib(out) == pytest.approx([80.5, 81.5, 47.0, 35.0])
        assert info["calibration"]["fx"] == pytest.approx(80.5) and info["calibration"]["source"] == arg


def test_unreadable_input_calibration_without_calib_is_one_line_error(foreign, tmp_path, capsys):
    code, out, err = run(["track", str(foreign), "--out", str(tmp_path / "run"), *FAST], capsys)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert str(foreign / "calib.txt") in lines[0]
    assert "KITTI" in lines[0] and "YAML" in lines[0] and "--calib" in lines[0]
    assert not (tmp_path / "run" / "traj.txt").exists()


def test_readable_input_calibration_loses_to_calib(seq, tmp_path, capsys):
    (tmp_path / "given.txt").write_text(GIVEN)
    out = tmp_path / "run"
    code, _, err = run(["track", str(seq), "--out", str(out), "--calib", str(tmp_path / "given.txt"), *FAST], capsys)
    assert code == 0, err
    assert "ignored the input's calibration" not in err
    assert run_calib(out) == pytest.approx([80.5, 81.5, 47.0, 35.0])
    out2 = tmp_path / "run2"
    code, _, err = run(["track", str(seq), "--out", str(out2), *FAST], capsys)
    assert code == 0, err
    assert run_calib(out2) == pytest.approx(CFG.intrinsics, abs=1e-5)


def test_kitti_calib_file_as_calib_option(seq, tmp_path, capsys):
    kitti = tmp_path / "kitti_calib.txt"
    kitti.write_text(KITTI_TWO_CAMERAS)
    out = tmp_path / "run"
    code, _, err = run(["track", str(seq), "--out", str(out), "--calib", str(kitti), *FAST], capsys)
    assert code == 0, err
    assert run_calib(out) == pytest.approx([70.0, 70.0, 47.5, 35.5])  # P0
    # a KITTI image_2 folder reads P2 from the same file
    kseq = tmp_path / "k"
    (kseq / "image_2").mkdir(parents=True)
    for i, png in enumerate(sorted((seq / "rgb").iterdir())):
        shutil.copy(png, kseq / "image_2" / f"{i:06d}.png")
    (kseq / "times.txt").write_text("".join(f"{i / 10:.6e}\n" for i in range(CFG.frames)))
    source = open_source(kseq, strict_calibration=False)
    assert load_calibration(kitti, source.size, camera=source.calibration_camera).fx == 90.0
    code, _, err = run(["track", str(kseq), "--out", str(tmp_path / "krun"), "--calib", str(kitti), *FAST], capsys)
    assert code == 0, err
    assert run_calib(tmp_path / "krun") == pytest.approx([90.0, 91.0, 48.0, 36.0])
    assert "ignored" not in err  # no calib.txt in the folder: nothing to warn about


def test_euroc_sensor_yaml_follows_the_same_rule(tmp_path):
    cam = tmp_path / "MH" / "mav0" / "cam0"
    (cam / "data").mkdir(parents=True)
    cv2.imwrite(str(cam / "data" / "1403636579763555584.png"), np.zeros((48, 64), np.uint8))
    (cam / "data.csv").write_text("#timestamp [ns],filename\n1403636579763555584,1403636579763555584.png\n")
    (cam / "sensor.yaml").write_text("intrinsics: [1, 1, 1, 1]\ndistortion_model: equidistant\n")
    with pytest.raises(InputError, match="sensor.yaml.*not supported.*--calib FILE or --calib auto"):
        open_source(tmp_path / "MH")
    lax = open_source(tmp_path / "MH", strict_calibration=False)
    assert lax.intrinsics_hint is None and "equidistant" in lax.calibration_problem
