"""Frame sources on tiny generated inputs: videos, image folders, TUM RGB-D, EuRoC."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from droidw_cli.errors import ConfigError, InputError
from droidw_cli.io.datasets import EurocSource, TumRgbdSource, associate_nearest
from droidw_cli.io.frames import CorruptFrameWarning
from droidw_cli.io.input import open_source
from droidw_cli.io.sources import ImageFolderSource, VideoSource, natural_key, stem_timestamps

H, W = 48, 64


def level_image(i: int) -> np.ndarray:
    """Flat grey frame whose level encodes its number (survives lossy codecs)."""
    return np.full((H, W, 3), 10 + 20 * i, np.uint8)


def textured(i: int, h: int = H, w: int = W) -> np.ndarray:
    rng = np.random.default_rng(i)
    return (rng.random((h, w, 3)) * 255).astype(np.uint8)


def write_video(path: Path, n: int, fourcc: str, fps: float = 25.0, frame=level_image) -> Path:
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), fps, (W, H))
    assert writer.isOpened(), f"cannot write {fourcc} video"
    for i in range(n):
        writer.write(frame(i))
    writer.release()
    return path


def write_images(folder: Path, names, frame=textured) -> list[np.ndarray]:
    folder.mkdir(parents=True, exist_ok=True)
    images = []
    for i, name in enumerate(names):
        img = frame(i)
        assert cv2.imwrite(str(folder / name), img[..., ::-1])  # RGB → BGR on disk
        images.append(img)
    return images


def levels(source) -> list[int]:
    return [int(round((f.image.mean() - 10) / 20)) for f in source]


# --------------------------------------------------------------------------- video


@pytest.mark.parametrize("suffix,fourcc", [(".avi", "MJPG"), (".mp4", "mp4v")])
def test_video_frames_and_timestamps(tmp_path, suffix, fourcc):
    src = open_source(write_video(tmp_path / f"clip{suffix}", 10, fourcc, fps=25.0))
    assert isinstance(src, VideoSource)
    assert len(src) == 10 and src.size == (H, W) and src.name == "clip" and src.intrinsics_hint is None
    frames = list(src)
    assert [f.index for f in frames] == list(range(10))
    assert np.allclose([f.timestamp for f in frames], np.arange(10) / 25.0)
    assert levels(frames) == list(range(10))
    assert all(f.image.shape == (H, W, 3) and f.image.dtype == np.uint8 and f.depth is None for f in frames)


def test_video_is_rgb(tmp_path):
    red_bgr = lambda i: np.dstack([np.zeros((H, W)), np.zeros((H, W)), np.full((H, W), 200)]).astype(np.uint8)
    f = next(iter(open_source(write_video(tmp_path / "red.avi", 2, "MJPG", frame=red_bgr))))
    assert f.image[..., 0].mean() > 150 and f.image[..., 2].mean() < 50


def test_video_reiteration_and_selection(tmp_path):
    path = write_video(tmp_path / "clip.avi", 10, "MJPG", frame=lambda i: textured(i)[..., ::-1])
    src = open_source(path)
    a, b = list(src), list(src)
    assert len(a) == len(b) == 10
    assert all(np.array_equal(x.image, y.image) and x.timestamp == y.timestamp for x, y in zip(a, b))
    sel = open_source(path, start=2, stride=3, max_frames=2)
    frames = list(sel)
    assert len(sel) == 2 and [f.index for f in frames] == [0, 1]
    assert np.allclose([f.timestamp for f in frames], [2 / 25.0, 5 / 25.0])
    assert np.array_equal(frames[1].image, a[5].image)
    assert len(open_source(path, start=1, stride=4)) == 3  # raw 1, 5, 9


def test_video_corrupt_frame_is_skipped(tmp_path):
    path = write_video(tmp_path / "clip.avi", 10, "MJPG", frame=lambda i: textured(i)[..., ::-1])
    data = bytearray(path.read_bytes())
    soi = [i for i in range(len(data) - 1) if data[i] == 0xFF and data[i + 1] == 0xD8]
    assert len(soi) == 10
    data[soi[4] : soi[4] + 600] = bytes(600)  # wreck the fifth JPEG frame
    path.write_bytes(bytes(data))
    src = open_source(path)
    with pytest.warns(CorruptFrameWarning, match="frame 4"):
        frames = list(src)
    assert [f.index for f in frames] == [0, 1, 2, 3, 5, 6, 7, 8, 9]
    assert frames[4].timestamp == pytest.approx(5 / 25.0)


def test_video_errors(tmp_path):
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"not a video" * 20)
    with pytest.raises(InputError, match="bad.mp4"):
        open_source(bad)
    with pytest.raises(InputError, match="no such file"):
        open_source(tmp_path / "missing.mp4")
    other = tmp_path / "notes.xyz"
    other.write_text("hello")
    with pytest.raises(InputError, match="unknown input type"):
        open_source(other)
    path = write_video(tmp_path / "clip.avi", 3, "MJPG")
    with pytest.raises(InputError, match="no frames left"):
        open_source(path, start=5)
    with pytest.raises(ConfigError, match="stride"):
        open_source(path, stride=0)
    with pytest.raises(ConfigError, match="fps"):
        open_source(path, fps=0.0)


# --------------------------------------------------------------------------- image folders


def test_natural_sort_and_index_timestamps(tmp_path):
    names = ["img10.png", "img2.png", "img1.png", "IMG3.png"]
    images = dict(zip(names, write_images(tmp_path / "seq", names)))
    (tmp_path / "seq" / "notes.txt").write_text("ignored")
    src = open_source(tmp_path / "seq", fps=10.0)
    assert isinstance(src, ImageFolderSource) and len(src) == 4 and src.name == "seq"
    frames = list(src)
    order = ["img1.png", "img2.png", "IMG3.png", "img10.png"]
    assert all(np.array_equal(f.image, images[n]) for f, n in zip(frames, order))
    assert np.allclose([f.timestamp for f in frames], np.arange(4) / 10.0)


def test_frame_number_names_use_index_over_fps(tmp_path):
    names = [f"{i:05d}.jpg" for i in range(6)]
    write_images(tmp_path / "seq", names)
    src = open_source(tmp_path / "seq", fps=20.0, stride=2)
    assert not src.timestamps_from_names
    assert np.allclose([f.timestamp for f in src], [0.0, 0.1, 0.2])  # raw index 0, 2, 4 over 20 fps


def test_unix_timestamp_names(tmp_path):
    stamps = ["1305031102.2", "1305031102.175304", "1305031102.211", "1305031102.3"]
    write_images(tmp_path / "seq", [s + ".png" for s in stamps])
    src = open_source(tmp_path / "seq")
    assert src.timestamps_from_names
    got = [f.timestamp for f in src]
    assert got == pytest.approx(sorted(float(s) for s in stamps), abs=1e-9)  # ordered by value, not by text


def test_stem_timestamp_rule():
    assert stem_timestamps(["0", "1", "2"]) is None  # frame numbers
    assert stem_timestamps(["a1", "2"]) is None
    assert np.allclose(stem_timestamps(["1305031102", "1305031103"]), [1305031102, 1305031103])
    assert np.allclose(stem_timestamps(["1403636579763555584"]), [1403636579.763555584])
    assert np.allclose(stem_timestamps(["0.5", "1.0"]), [0.5, 1.0])
    assert natural_key("a2") < natural_key("a10")


def test_folder_corrupt_image_is_skipped_and_reiterates(tmp_path):
    names = [f"f{i}.png" for i in range(5)]
    images = write_images(tmp_path / "seq", names)
    bad = tmp_path / "seq" / "f2.png"
    bad.write_bytes(bad.read_bytes()[:60])  # truncated PNG
    src = open_source(tmp_path / "seq")
    assert len(src) == 5
    for _ in range(2):  # each pass reopens and warns again
        with pytest.warns(CorruptFrameWarning, match="f2.png"):
            frames = list(src)
        assert [f.index for f in frames] == [0, 1, 3, 4]
        assert np.array_equal(frames[2].image, images[3])


def test_folder_mismatched_size_is_skipped(tmp_path):
    write_images(tmp_path / "seq", ["a0.png", "a1.png"])
    cv2.imwrite(str(tmp_path / "seq" / "a2.png"), textured(9, 20, 20))
    with pytest.warns(CorruptFrameWarning, match="differs"):
        assert [f.index for f in open_source(tmp_path / "seq")] == [0, 1]


def test_folder_errors_and_calib_hint(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no images"):
        open_source(tmp_path / "empty")
    write_images(tmp_path / "seq", ["a.png", "b.png"])
    with pytest.raises(InputError, match="single image"):
        open_source(tmp_path / "seq" / "a.png")
    (tmp_path / "seq" / "calib.txt").write_text("50 51 31.5 23.5\n")
    hint = open_source(tmp_path / "seq").intrinsics_hint
    assert (hint.fx, hint.fy, hint.cx, hint.cy) == (50, 51, 31.5, 23.5)
    (tmp_path / "seq" / "calib.txt").write_text("50 51 900 23.5\n")
    with pytest.raises(InputError, match="cx=900"):
        open_source(tmp_path / "seq")


# --------------------------------------------------------------------------- TUM / Bonn


def make_tum(root: Path) -> dict:
    (root / "rgb").mkdir(parents=True)
    (root / "depth").mkdir()
    rgb_t = [1.000, 1.033, 1.066, 1.500]
    depth_t = [1.005, 1.040, 1.070]  # the last RGB has no depth within 0.02 s
    images = {}
    for i, t in enumerate(rgb_t):
        images[t] = textured(i)
        cv2.imwrite(str(root / "rgb" / f"{t:.6f}.png"), images[t][..., ::-1])
    for i, t in enumerate(depth_t):
        d = np.full((H, W), 5000 * (i + 1), np.uint16)
        d[:5, :5] = 0  # invalid
        cv2.imwrite(str(root / "depth" / f"{t:.6f}.png"), d)
    head = "# color images\n# file: 'x.bag'\n# timestamp filename\n"
    (root / "rgb.txt").write_text(head + "".join(f"{t:.6f} rgb/{t:.6f}.png\n" for t in rgb_t))
    (root / "depth.txt").write_text(head + "".join(f"{t:.6f} depth/{t:.6f}.png\n" for t in depth_t))
    return images


def test_tum_rgbd_association(tmp_path):
    images = make_tum(tmp_path / "rgbd_dataset")
    src = open_source(tmp_path / "rgbd_dataset")
    assert isinstance(src, TumRgbdSource) and len(src) == 4 and src.name == "rgbd_dataset"
    frames = list(src)
    assert [f.timestamp for f in frames] == pytest.approx([1.0, 1.033, 1.066, 1.5])
    assert all(np.array_equal(f.image, images[t]) for f, t in zip(frames, sorted(images)))
    for f, metres in zip(frames[:3], (1.0, 2.0, 3.0)):
        assert f.depth.dtype == np.float32 and f.depth.shape == (H, W)
        assert f.depth[10, 10] == pytest.approx(metres) and np.all(f.depth[:5, :5] == 0)
    assert frames[3].depth is None
    assert src.intrinsics_hint is None
    (tmp_path / "rgbd_dataset" / "calib.txt").write_text("52 52 31.5 23.5 0.1 -0.01 0 0\n")
    via_txt = open_source(tmp_path / "rgbd_dataset" / "rgb.txt", start=1, max_frames=2)
    assert via_txt.intrinsics_hint.distortion == (0.1, -0.01, 0.0, 0.0)
    assert [f.timestamp for f in via_txt] == pytest.approx([1.033, 1.066])
    # a selection past the end says so, not that the folder's calibration misfits a 0-pixel image
    with pytest.raises(InputError, match="no frames left after start=10"):
        open_source(tmp_path / "rgbd_dataset", start=10)


def test_tum_bad_listing(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "rgb.txt").write_text("1.0\n")
    with pytest.raises(InputError, match="rgb.txt:1"):
        open_source(tmp_path / "d")


def test_associate_nearest_matches_brute_force():
    rng = np.random.default_rng(3)
    q, r = np.sort(rng.random(200) * 10), rng.random(150) * 10
    got = associate_nearest(q, r, 0.02)
    dist = np.abs(q[:, None] - r[None, :])
    best = dist.argmin(1)
    want = np.where(dist[np.arange(len(q)), best] <= 0.02, best, -1)
    assert np.array_equal(got, want) and (got >= 0).any() and (got < 0).any()
    assert np.array_equal(associate_nearest(q[:3], np.array([q[1]]), 0.0), [-1, 0, -1])


# --------------------------------------------------------------------------- EuRoC

SENSOR_YAML = """# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)
T_BS:
  cols: 4
  rows: 4
  data: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
rate_hz: 20
resolution: [64, 48]
camera_model: pinhole
intrinsics: [45.8654, 45.7296, 36.7215, 24.8375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
"""


def test_euroc_layouts(tmp_path):
    cam = tmp_path / "MH_01" / "mav0" / "cam0"
    (cam / "data").mkdir(parents=True)
    stamps = [1403636579763555584, 1403636579813555456, 1403636579863555584]
    greys = []
    for i, ns in enumerate(stamps):
        g = textured(i)[..., 0]
        cv2.imwrite(str(cam / "data" / f"{ns}.png"), g)
        greys.append(g)
    (cam / "data.csv").write_text("#timestamp [ns],filename\n" + "".join(f"{ns},{ns}.png\n" for ns in stamps))
    (cam / "sensor.yaml").write_text(SENSOR_YAML)
    for path in (tmp_path / "MH_01", tmp_path / "MH_01" / "mav0", cam):
        src = open_source(path)
        assert isinstance(src, EurocSource) and len(src) == 3 and src.size == (H, W) and src.name == "MH_01"
        frames = list(src)
        assert [f.timestamp for f in frames] == pytest.approx([ns / 1e9 for ns in stamps], abs=1e-6)
        assert frames[1].timestamp - frames[0].timestamp == pytest.approx(0.05, abs=1e-6)
        assert all(f.image.shape == (H, W, 3) and np.array_equal(f.image[..., 2], g) for f, g in zip(frames, greys))
        assert np.array_equal(frames[0].image[..., 0], frames[0].image[..., 1])
        hint = src.intrinsics_hint
        assert hint.as_array() == pytest.approx([45.8654, 45.7296, 36.7215, 24.8375])
        assert len(hint.distortion) == 4 and hint.distortion[0] == pytest.approx(-0.28340811)
