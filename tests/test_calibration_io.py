"""Calibration files: parsing (text, YAML), validation, writing."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.errors import InputError
from droidw_cli.io.calibration import (
    Calibration,
    centre_principal_point,
    default_calibration,
    load_calibration,
    write_calibration,
)


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    "text,dist",
    [
        ("517.3 516.5 318.6 255.3\n", ()),
        ("# TUM fr1\n517.3, 516.5, 318.6, 255.3  # fx fy cx cy\n", ()),
        ("517.3 516.5 318.6 255.3 0.2624 -0.9531 -0.0054 0.0026\n", (0.2624, -0.9531, -0.0054, 0.0026)),
        ("517.3,516.5,318.6,255.3,0.2624,-0.9531,-0.0054,0.0026,1.1633", (0.2624, -0.9531, -0.0054, 0.0026, 1.1633)),
    ],
)
def test_text_format(tmp_path, text, dist):
    calib = load_calibration(write(tmp_path, "calib.txt", text), image_size=(480, 640))
    assert calib.as_array() == pytest.approx([517.3, 516.5, 318.6, 255.3])
    assert calib.distortion == pytest.approx(dist)
    assert calib.has_distortion == bool(dist)


def test_yaml_formats(tmp_path):
    plain = write(tmp_path, "cam.yaml", "fx: 500\nfy: 501\ncx: 320\ncy: 240\ndistortion: [0.1, -0.2, 0.001, 0.002, 0.03]\n")
    c = load_calibration(plain, (480, 640))
    assert (c.fx, c.fy, c.cx, c.cy) == (500, 501, 320, 240) and c.distortion == (0.1, -0.2, 0.001, 0.002, 0.03)
    euroc = write(tmp_path, "sensor.yaml", "camera_model: pinhole\nintrinsics: [458.654, 457.296, 367.215, 248.375]\n"
                  "distortion_model: radial-tangential\ndistortion_coefficients: [-0.2834, 0.0739, 0.0001, 0.00001]\n")
    c = load_calibration(euroc, (480, 752))
    assert c.as_array() == pytest.approx([458.654, 457.296, 367.215, 248.375]) and c.distortion[0] == -0.2834
    orb = write(tmp_path, "orb.yaml", "%YAML:1.0\nCamera.fx: 517.3\nCamera.fy: 516.5\nCamera.cx: 318.6\nCamera.cy: 255.3\n"
                "Camera.k1: 0.26\nCamera.k2: -0.95\nCamera.p1: -0.005\nCamera.p2: 0.003\n")
    c = load_calibration(orb)
    assert c.fx == 517.3 and c.distortion == (0.26, -0.95, -0.005, 0.003)


def test_auto_returns_none():
    assert load_calibration("auto", (480, 640)) is None
    assert load_calibration("AUTO") is None


@pytest.mark.parametrize(
    "text,message",
    [
        ("500 500 900 240", "cx=900 is outside the 640-pixel-wide image"),
        ("500 500 320 -3", "cy=-3 is outside the 480-pixel-high image"),
        ("0 500 320 240", "fx=0 must be positive"),
        ("500 -1 320 240", "fy=-1 must be positive"),
        ("500 nan 320 240", "fy=nan is not a finite number"),
        ("500 500 320", "expected 4, 8 or 9 numbers"),
        ("500 500 320 240 0.1", "expected 4, 8 or 9 numbers"),
        ("500 500 320 abc", "'abc' is not a number"),
        ("500 500 320 240\n500 500 320 240", "expected one line"),
        ("# nothing\n", "holds no numbers"),
        ("1e9 1e9 320 240", "field of view"),  # accepted before: every pose degenerate
        ("20 20 320 240", "fx=20 px gives a"),  # under 0.05 × 640: a wider view than a pinhole can have
        ("500 2000 320 240", "differ by more than"),
    ],
)
def test_bad_text_values(tmp_path, text, message):
    path = write(tmp_path, "calib.txt", text)
    with pytest.raises(InputError, match="calib.txt") as err:
        load_calibration(path, image_size=(480, 640))
    assert message in str(err.value)


@pytest.mark.parametrize(
    "text,message",
    [
        ("fx: 500\nfy: 500\ncx: 320\n", "missing cy"),
        ("intrinsics: [500, 500, 320]\n", "intrinsics must be [fx, fy, cx, cy]"),
        ("fx: big\nfy: 500\ncx: 320\ncy: 240\n", "fx='big' is not a number"),
        ("intrinsics: [1, 1, 1, 1]\ndistortion_model: equidistant\n", "not supported"),
        ("fx: 500\nfy: 500\ncx: 320\ncy: 240\ndistortion: [0.1, 0.2]\n", "4 or 5 coefficients"),
        ("fx: [unclosed\n", "not valid YAML"),
    ],
)
def test_bad_yaml(tmp_path, text, message):
    with pytest.raises(InputError, match="cam.yaml") as err:
        load_calibration(write(tmp_path, "cam.yaml", text), (480, 640))
    assert message in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_calibration(tmp_path / "nope.txt")


def test_write_round_trip(tmp_path):
    calib = Calibration(458.654, 457.296, 367.215, 248.375, (-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05))
    path = tmp_path / "out" / "calib.txt"
    write_calibration(path, calib)
    assert load_calibration(path, (480, 752)) == calib
    assert len(path.read_text().strip().splitlines()) == 1
    assert sorted(p.name for p in path.parent.iterdir()) == ["calib.txt"]  # no temp files left


def test_dataclass_helpers():
    calib = Calibration(100.0, 110.0, 63.5, 47.5, (0.1, 0.0, 0.0, 0.0))
    assert calib.camera_matrix() @ np.array([0.0, 0.0, 1.0]) == pytest.approx([63.5, 47.5, 1.0])
    half = calib.scaled((96, 128), (48, 64))
    assert half.as_array() == pytest.approx([50.0, 55.0, 31.5, 23.5]) and half.distortion == calib.distortion
    with pytest.raises(ValueError):
        Calibration(-1.0, 1.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        Calibration(1.0, 1.0, 0.0, 0.0, (0.1,))
    assert centre_principal_point(480, 640) == (319.5, 239.5)
    guess = default_calibration(480, 640)
    assert (guess.fx, guess.fy, guess.cx, guess.cy) == pytest.approx((576.0, 576.0, 319.5, 239.5))
