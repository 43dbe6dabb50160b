"""``droidw export colmap``: the text model read back (world-to-camera quaternions, points3D reprojection), masks.

Runs: :mod:`trainer_runs` (a tracked 320×240 walker clip, working size 160×120).
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from cli_run import run as cli
from droidw_cli.export.pointcloud import CloudParams, build_cloud
from trainer_runs import SIZE, calib_values, cell_centres_in_input, gt_mask, run_arrays, tracked_run, with_calibration


@pytest.fixture(scope="module")
def mono(tmp_path_factory):
    return tracked_run(tmp_path_factory)


def export(run, out):
    from droidw_cli.cli import main

    try:
        main(["export", "colmap", str(run), "--out", str(out), "--quiet"])
    except SystemExit as exc:
        assert exc.code in (0, None)
    return read_model(out / "sparse" / "0")


@pytest.fixture(scope="module")
def exported(mono, tmp_path_factory):
    out = tmp_path_factory.mktemp("colmap") / "out"
    return out, export(mono[1], out)


def _data_lines(path):
    return [line for line in path.read_text().splitlines() if not line.startswith("#")]


def read_model(folder) -> dict:
    """COLMAP's text model, read as COLMAP documents it."""
    cams = [line.split() for line in _data_lines(folder / "cameras.txt")]
    cameras = {int(c[0]): (c[1], int(c[2]), int(c[3]), [float(v) for v in c[4:]]) for c in cams}
    lines = _data_lines(folder / "images.txt")
    images = {}
    for head, points in zip(lines[0::2], lines[1::2]):
        f = head.split()
        p = np.array(points.split(), dtype=np.float64).reshape(-1, 3)
        images[int(f[0])] = {"q": np.array(f[1:5], float), "t": np.array(f[5:8], float), "camera": int(f[8]),
                             "name": f[9], "xy": p[:, :2], "ids": p[:, 2].astype(int)}
    points = {}
    for line in _data_lines(folder / "points3D.txt"):
        f = line.split()
        track = np.array(f[8:], dtype=int).reshape(-1, 2)
        points[int(f[0])] = {"xyz": np.array(f[1:4], float), "rgb": np.array(f[4:7], int), "track": track}
    return {"cameras": cameras, "images": images, "points": points}


def quat_to_rotation(q: np.ndarray) -> np.ndarray:
    """Hamilton unit quaternion (w, x, y, z) → rotation matrix."""
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def colmap_project(camera, image, xyz: np.ndarray) -> np.ndarray:
    """COLMAP's projection (PINHOLE / OPENCV), COLMAP pixels (a pixel's centre at +0.5)."""
    model, _, _, params = camera
    cam = xyz @ quat_to_rotation(image["q"]).T + image["t"]
    x, y = cam[:, 0] / cam[:, 2], cam[:, 1] / cam[:, 2]
    if model == "OPENCV":
        k1, k2, p1, p2 = params[4:8]
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        x, y = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    fx, fy, cx, cy = params[:4]
    return np.stack([fx * x + cx, fy * y + cy], -1)


def test_camera_and_files(mono, exported):
    _, run = mono
    out, model = exported
    fx, fy, cx, cy = calib_values(run)[:4]
    assert model["cameras"] == {1: ("PINHOLE", SIZE[1], SIZE[0], [fx, fy, cx + 0.5, cy + 0.5])}
    arrays = run_arrays(run)
    assert len(model["images"]) == len(arrays["index"]) >= 3
    for image in model["images"].values():
        assert image["camera"] == 1
        assert cv2.imread(str(out / "images" / image["name"])).shape == (*SIZE, 3)
        mask = cv2.imread(str(out / "masks" / f"{image['name']}.png"), cv2.IMREAD_UNCHANGED)  # COLMAP: NAME.png
        assert mask.shape == SIZE and set(np.unique(mask)) <= {0, 255}


def test_poses_are_world_to_camera(mono, exported):
    _, run = mono
    poses = run_arrays(run)["poses_c2w"]
    images = exported[1]["images"]
    for image_id, image in images.items():
        r = quat_to_rotation(image["q"])
        c2w = poses[image_id - 1]
        np.testing.assert_allclose(-r.T @ image["t"], c2w[:3, 3], atol=1e-9)  # the camera centre
        np.testing.assert_allclose(r, c2w[:3, :3].T, atol=1e-9)


def test_points3d_reproject_into_their_images(mono, exported):
    _, run = mono
    model = exported[1]
    arrays = run_arrays(run)
    cloud = build_cloud(arrays, CloudParams())
    assert len(model["points"]) == int(cloud.static.sum()) > 20
    kf, rows, cols = np.nonzero(cloud.static.reshape(arrays["disps"].shape))
    u0, v0 = cell_centres_in_input(run, rows, cols)  # where the run's own depth map had each point
    camera = model["cameras"][1]
    for n, (pid, point) in enumerate(sorted(model["points"].items())):
        (image_id, idx), = point["track"]
        image = model["images"][image_id]
        assert image["ids"][idx] == pid  # the track and the image's 2D points agree
        uv = colmap_project(camera, image, point["xyz"][None])[0]
        np.testing.assert_allclose(uv, image["xy"][idx], atol=2e-3)  # 3 decimals in the file
        assert image_id - 1 == kf[n]
        np.testing.assert_allclose(uv - 0.5, [u0[n], v0[n]], atol=0.01)


def test_masks_are_black_on_the_movers(mono, exported):
    seq, run = mono
    out, model = exported
    index = run_arrays(run)["index"]
    covered = total = 0
    for image_id, image in model["images"].items():
        mask = cv2.imread(str(out / "masks" / f"{image['name']}.png"), cv2.IMREAD_UNCHANGED)
        gt = gt_mask(seq, int(index[image_id - 1]))
        covered += int(((mask == 0) & gt).sum())
        total += int(gt.sum())
    assert total > 0 and covered / total > 0.8


def test_distortion_gives_an_opencv_camera_and_distorted_points(mono, tmp_path):
    _, run = mono
    fx, fy, cx, cy = calib_values(run)[:4]
    dist = [-0.05, 0.01, 0.001, -0.002]
    model = export(with_calibration(run, tmp_path / "run", [fx, fy, cx, cy, *dist]), tmp_path / "out")
    camera = model["cameras"][1]
    assert camera[0] == "OPENCV" and camera[3][4:] == dist
    moved = []
    for pid, point in list(model["points"].items())[:300]:
        (image_id, idx), = point["track"]
        image = model["images"][image_id]
        np.testing.assert_allclose(colmap_project(camera, image, point["xyz"][None])[0], image["xy"][idx], atol=2e-3)
        pinhole = colmap_project(("PINHOLE", *camera[1:]), image, point["xyz"][None])[0]
        moved.append(np.abs(pinhole - image["xy"][idx]).max())
    assert np.median(moved) > 0.05  # the 2D points carry the distortion


def test_errors(mono, tmp_path, capsys):
    _, run = mono
    out = tmp_path / "out"
    code, _, err = cli(["export", "colmap", str(tmp_path / "nowhere"), "--out", str(out)], capsys)
    assert code == 2 and "no such run folder" in err and not out.exists()
    (tmp_path / "taken").mkdir()
    (tmp_path / "taken" / "x").write_text("")
    code, _, err = cli(["export", "colmap", str(run), "--out", str(tmp_path / "taken")], capsys)
    assert code == 2 and "not empty" in err


def test_the_distortion_the_run_removed_comes_from_the_input_calibration(mono, tmp_path):
    """A run's calib.txt holds the undistorted intrinsics; the distortion is the input calibration's."""
    import shutil

    from trainer_runs import with_input

    seq, run = mono
    assert json.loads((run / "run.json").read_text())["calibration"]["source"] == "input"
    bent = tmp_path / "seq"
    shutil.copytree(seq, bent)
    dist = [-0.05, 0.01, 0.001, -0.002]
    k = [float(v) for v in (seq / "calib.txt").read_text().split()]
    (bent / "calib.txt").write_text(" ".join(repr(v) for v in [*k[:4], *dist]) + "\n")
    camera = export(with_input(run, tmp_path / "run", str(bent)), tmp_path / "out")["cameras"][1]
    assert camera[0] == "OPENCV" and camera[3][4:] == dist
    (bent / "calib.txt").write_text(" ".join(repr(v) for v in [k[0] * 1.1, *k[1:4], *dist]) + "\n")
    camera = export(with_input(run, tmp_path / "run2", str(bent)), tmp_path / "out2")["cameras"][1]
    assert camera[0] == "PINHOLE"  # another camera than the run's: its distortion is not taken
