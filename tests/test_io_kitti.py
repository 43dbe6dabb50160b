"""KITTI odometry input: sequence detection, calibration from P0 / P2, times.txt, grey → RGB, clear errors."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from droidw_cli.errors import InputError
from droidw_cli.io.calibration import load_calibration
from droidw_cli.io.datasets import KittiSource
from droidw_cli.io.input import open_source
from droidw_cli.io.sources import ImageFolderSource

H, W = 48, 64
TIMES = [0.0, 0.1036224, 0.2072447, 0.3108671]
# KITTI-style projections: P0 the grey left camera, P2 the colour left camera (other intrinsics, a baseline term)
P0 = [[52.0, 0.0, 31.0, 0.0], [0.0, 53.0, 23.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
P1 = [[52.0, 0.0, 31.0, -28.08], [0.0, 53.0, 23.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
P2 = [[60.0, 0.0, 32.5, 2.6], [0.0, 61.0, 24.5, -0.01], [0.0, 0.0, 1.0, 0.0004]]


def matrix_line(name: str, m) -> str:
    return f"{name}: " + " ".join(f"{v:.12e}" for v in np.asarray(m, float).ravel()) + "\n"


def kitti_calib(p2=P2) -> str:
    return "".join(matrix_line(n, m) for n, m in (("P0", P0), ("P1", P1), ("P2", p2), ("P3", P1),
                                                   ("Tr", np.eye(4)[:3])))


def grey(i: int) -> np.ndarray:
    return (np.random.default_rng(i).random((H, W)) * 255).astype(np.uint8)


def colour(i: int) -> np.ndarray:
    return (np.random.default_rng(100 + i).random((H, W, 3)) * 255).astype(np.uint8)


def make_kitti(root: Path, cams=(0,), n: int = len(TIMES), calib: str | None = None, times=TIMES) -> Path:
    """A KITTI odometry sequence folder: image_<cam>/NNNNNN.png, times.txt, calib.txt."""
    root.mkdir(parents=True, exist_ok=True)
    for cam in cams:
        (root / f"image_{cam}").mkdir()
        for i in range(n):
            img = grey(i) if cam in (0, 1) else colour(i)[..., ::-1]  # RGB → BGR on disk
            assert cv2.imwrite(str(root / f"image_{cam}" / f"{i:06d}.png"), img)
    if times is not None:
        (root / "times.txt").write_text("".join(f"{t:.6e}\n" for t in times))
    if calib is not None:
        (root / "calib.txt").write_text(calib)
    return root


def test_grey_sequence_reads_p0_times_and_three_channels(tmp_path):
    seq = make_kitti(tmp_path / "00", calib=kitti_calib())
    src = open_source(seq)
    assert isinstance(src, KittiSource) and len(src) == 4 and src.size == (H, W) and src.name == "00"
    assert src.intrinsics_hint.as_array() == pytest.approx([52.0, 53.0, 31.0, 23.0])
    assert src.intrinsics_hint.distortion == ()
    frames = list(src)
    assert [f.timestamp for f in frames] == pytest.approx(TIMES, abs=1e-6)
    assert [f.index for f in frames] == [0, 1, 2, 3]
    for i, f in enumerate(frames):
        assert f.image.shape == (H, W, 3) and f.image.dtype == np.uint8 and f.depth is None
        assert all(np.array_equal(f.image[..., c], grey(i)) for c in range(3))
    picked = open_source(seq, start=1, stride=2)
    assert [f.timestamp for f in picked] == pytest.approx(TIMES[1::2], abs=1e-6)


def test_image_0_is_preferred_and_image_2_reads_p2(tmp_path):
    both = make_kitti(tmp_path / "both", cams=(0, 2), calib=kitti_calib())
    src = open_source(both)
    assert src.calibration_camera == 0 and src.intrinsics_hint.fx == 52.0
    assert np.array_equal(next(iter(src)).image[..., 0], grey(0))
    # the image_2 folder itself picks the colour camera, its P2, the parent's times
    colour_src = open_source(both / "image_2")
    assert isinstance(colour_src, KittiSource) and colour_src.name == "both"
    assert colour_src.intrinsics_hint.as_array() == pytest.approx([60.0, 61.0, 32.5, 24.5])
    assert np.array_equal(next(iter(colour_src)).image, colour(0))
    assert [f.timestamp for f in colour_src] == pytest.approx(TIMES, abs=1e-6)
    # image_0 itself is the same as its sequence
    assert open_source(both / "image_0").intrinsics_hint == src.intrinsics_hint
    only_colour = make_kitti(tmp_path / "colour", cams=(2,), calib=kitti_calib())
    assert open_source(only_colour).intrinsics_hint.fx == 60.0


def test_image_folder_without_times_beside_it_is_a_plain_folder(tmp_path):
    seq = make_kitti(tmp_path / "seq", times=None)
    src = open_source(seq / "image_0", fps=10.0)
    assert isinstance(src, ImageFolderSource)
    assert [f.timestamp for f in src] == pytest.approx([0.0, 0.1, 0.2, 0.3])


def test_times_problems_are_clear_errors(tmp_path):
    with pytest.raises(InputError, match="needs times.txt"):
        open_source(make_kitti(tmp_path / "a", times=None, calib=kitti_calib()))
    with pytest.raises(InputError, match=r"times.txt: 3 timestamps for 4 images in image_0/"):
        open_source(make_kitti(tmp_path / "b", times=TIMES[:3], calib=kitti_calib()))
    garbled = make_kitti(tmp_path / "c", calib=kitti_calib())
    (garbled / "times.txt").write_text("0.0\n0.1\nabc\n0.3\n")
    with pytest.raises(InputError, match=r"times.txt:3: expected one timestamp in seconds, got 'abc'"):
        open_source(garbled)
    (garbled / "times.txt").write_text("0.0\n0.2\n0.1\n0.3\n")
    with pytest.raises(InputError, match=r"times.txt:3: timestamp 0.1 does not increase"):
        open_source(garbled)
    (garbled / "times.txt").write_text("\n")
    with pytest.raises(InputError, match="holds no timestamps"):
        open_source(garbled)
    with pytest.raises(InputError, match="no images in this KITTI image folder"):
        open_source(make_kitti(tmp_path / "d", n=0, calib=kitti_calib()))


def test_calibration_problems(tmp_path):
    missing = make_kitti(tmp_path / "missing")
    with pytest.raises(InputError, match="no calib.txt.*--calib FILE or --calib auto"):
        open_source(missing)
    lax = open_source(missing, strict_calibration=False)
    assert lax.intrinsics_hint is None and lax.calibration_problem is None  # --calib given: nothing to warn about
    garbled = make_kitti(tmp_path / "garbled", calib="P0: 1 2 three\n")
    with pytest.raises(InputError) as err:
        open_source(garbled)
    message = str(err.value)
    assert str(garbled / "calib.txt") in message and "KITTI" in message and "YAML" in message
    assert "\n" not in message
    lax = open_source(garbled, strict_calibration=False)
    assert lax.intrinsics_hint is None and "calib.txt:1" in lax.calibration_problem
    no_p2 = make_kitti(tmp_path / "nop2", cams=(2,), calib=matrix_line("P0", P0))
    with pytest.raises(InputError, match="no P2 line"):
        open_source(no_p2)


def test_load_calibration_reads_kitti_files(tmp_path):
    path = tmp_path / "calib.txt"
    path.write_text(kitti_calib())
    assert load_calibration(path).as_array() == pytest.approx([52.0, 53.0, 31.0, 23.0])
    assert load_calibration(path, (H, W), camera=2).as_array() == pytest.approx([60.0, 61.0, 32.5, 24.5])
    for text, message in [
        (matrix_line("P0", np.ravel(P0)[:11]), "P0 needs 12 numbers (a 3×4 matrix, row-major), got 11"),
        (matrix_line("P0", [[52.0, 3.0, 31.0, 0.0], [0.0, 53.0, 23.0, 0.0], [0.0, 0.0, 1.0, 0.0]]),
         "not a rectified pinhole projection"),
        (matrix_line("P0", [[52.0, 0.0, 31.0, 0.0], [0.0, 53.0, 23.0, 0.0], [0.0, 0.0, 2.0, 0.0]]),
         "not a rectified pinhole projection"),
        (kitti_calib() + "just words\n", "calib.txt:6: expected 'NAME: numbers'"),
        (matrix_line("P0", [[52.0, 0.0, 900.0, 0.0], [0.0, 53.0, 23.0, 0.0], [0.0, 0.0, 1.0, 0.0]]), "cx=900"),
    ]:
        path.write_text(text)
        with pytest.raises(InputError, match="calib.txt") as err:
            load_calibration(path, (H, W))
        assert message in str(err.value)
