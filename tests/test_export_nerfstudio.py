"""``droidw export nerfstudio``: transforms.json read back with nerfstudio's conventions, masks, depth, errors.

Runs: :mod:`trainer_runs` (a tracked 320×240 walker clip, working size 160×120).
"""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from cli_run import run as cli
from droidw_cli.export.pointcloud import CloudParams, build_cloud
from trainer_runs import (SIZE, calib_values, cell_centres_in_input, gt_mask, listing, opencv_projection, run_arrays,
                          tracked_run, with_calibration, with_input)


@pytest.fixture(scope="module")
def mono(tmp_path_factory):
    return tracked_run(tmp_path_factory)


@pytest.fixture(scope="module")
def exported(mono, tmp_path_factory):
    out = tmp_path_factory.mktemp("ns") / "out"
    from droidw_cli.cli import main

    try:
        main(["export", "nerfstudio", str(mono[1]), "--out", str(out), "--quiet"])
    except SystemExit as exc:
        assert exc.code in (0, None)
    return out, json.loads((out / "transforms.json").read_text())


def test_every_file_it_names_exists_at_the_input_size(mono, exported):
    plyfile = pytest.importorskip("plyfile")
    seq, run = mono
    out, doc = exported
    arrays = run_arrays(run)
    assert doc["camera_model"] == "PINHOLE" and (doc["h"], doc["w"]) == SIZE
    assert len(doc["frames"]) == len(arrays["index"]) >= 3  # every keyframe
    frames = listing(seq, "rgb")
    for f, index in zip(doc["frames"], arrays["index"]):
        image = cv2.imread(str(out / f["file_path"]), cv2.IMREAD_UNCHANGED)
        mask = cv2.imread(str(out / f["mask_path"]), cv2.IMREAD_UNCHANGED)
        assert image.shape == (*SIZE, 3) and mask.shape == SIZE and mask.dtype == np.uint8
        assert set(np.unique(mask)) <= {0, 255}
        np.testing.assert_array_equal(image, cv2.imread(str(frames[index])))  # the input frame itself
        assert "depth_file_path" not in f  # a monocular run has no metric depth
    assert "depth_unit_scale_factor" not in doc
    ply = plyfile.PlyData.read(str(out / doc["ply_file_path"]))
    static = build_cloud(arrays, CloudParams()).part("static")
    assert ply["vertex"].count == len(static.xyz) > 0
    assert not list(out.parent.glob(".*"))  # no staging folder left


def test_intrinsics_are_the_calibration_in_nerfstudio_pixels(mono, exported):
    _, run = mono
    fx, fy, cx, cy = calib_values(run)[:4]
    doc = exported[1]
    assert (doc["fl_x"], doc["fl_y"]) == (fx, fy)
    assert (doc["cx"], doc["cy"]) == (cx + 0.5, cy + 0.5)  # nerfstudio: a pixel's centre at +0.5


def nerfstudio_project(doc: dict, frame: dict, xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Project world points as nerfstudio reads transforms.json: OpenGL camera-to-world (x right, y up, the camera
    looking down −z), pixel centres at +0.5.  Returns (P, 2) OpenCV pixels (centres at integers) and the depth."""
    c2w = np.asarray(frame["transform_matrix"], dtype=np.float64)
    w2c = np.linalg.inv(c2w)
    cam = xyz @ w2c[:3, :3].T + w2c[:3, 3]
    depth = -cam[:, 2]
    u = doc["fl_x"] * cam[:, 0] / depth + doc["cx"]
    v = doc["cy"] - doc["fl_y"] * cam[:, 1] / depth  # y up in the camera, down in the image
    return np.stack([u, v], -1) - 0.5, depth


def test_static_points_reproject_as_the_run_projects_them(mono, exported):
    _, run = mono
    doc = exported[1]
    arrays = run_arrays(run)
    cloud = build_cloud(arrays, CloudParams())
    kf, rows, cols = np.nonzero(cloud.static.reshape(arrays["disps"].shape))  # each static point's own cell
    xyz = cloud.xyz[cloud.static].astype(np.float64)
    checked = 0
    for k in np.unique(kf)[:2]:
        own = kf == k
        uv, depth = nerfstudio_project(doc, doc["frames"][k], xyz[own])
        assert (depth > 0).all()
        u0, v0 = cell_centres_in_input(run, rows[own], cols[own])  # where the run's depth map put them
        np.testing.assert_allclose(uv, np.stack([u0, v0], -1), atol=0.05)
        other = k + 1  # a second frame: the run's own OpenCV projection
        uv2, depth2 = nerfstudio_project(doc, doc["frames"][other], xyz[own])
        ahead = depth2 > 0
        assert ahead.mean() > 0.9
        np.testing.assert_allclose(uv2[ahead], opencv_projection(run, other, xyz[own][ahead]), atol=0.05)
        inside = ahead & (uv2[:, 0] >= 0) & (uv2[:, 0] < SIZE[1]) & (uv2[:, 1] >= 0) & (uv2[:, 1] < SIZE[0])
        checked += int(inside.sum())
    assert checked > 20


def test_masks_are_black_on_the_movers(mono, exported):
    seq, run = mono
    out, doc = exported
    arrays = run_arrays(run)
    covered = gt_total = lost = static_total = 0
    for k, f in enumerate(doc["frames"]):
        mask = cv2.imread(str(out / f["mask_path"]), cv2.IMREAD_UNCHANGED)
        grid = arrays["dynamic"][k]
        # every cell the run marked dynamic is black at its centre; cells two away from any are white there
        near = cv2.dilate(grid.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
        for cells, value in ((grid, 0), (~near, 255)):
            rows, cols = np.nonzero(cells)
            u, v = cell_centres_in_input(run, rows, cols)
            ok = (u >= 0) & (u < SIZE[1]) & (v >= 0) & (v < SIZE[0])
            assert (mask[np.rint(v[ok]).astype(int), np.rint(u[ok]).astype(int)] == value).all()
        gt = gt_mask(seq, int(arrays["index"][k]))
        covered += int(((mask == 0) & gt).sum())
        gt_total += int(gt.sum())
        lost += int(((mask == 0) & ~gt).sum())
        static_total += int((~gt).sum())
    assert gt_total > 0
    assert covered / gt_total > 0.8  # the ground-truth movers are ignored
    assert lost / static_total < 0.5 * covered / gt_total  # and most of the static scene is kept


def test_rgbd_run_gets_millimetre_depth(tmp_path_factory, tmp_path, capsys):
    seq, run = tracked_run(tmp_path_factory, depth=True)
    out = tmp_path / "ns"
    code, _, err = cli(["export", "nerfstudio", str(run), "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    doc = json.loads((out / "transforms.json").read_text())
    assert doc["depth_unit_scale_factor"] == 0.001
    depths = listing(seq, "depth")
    index = run_arrays(run)["index"]
    assert all("depth_file_path" in f for f in doc["frames"])
    for f, i in zip(doc["frames"], index):
        mm = cv2.imread(str(out / f["depth_file_path"]), cv2.IMREAD_UNCHANGED)
        sensor = cv2.imread(str(depths[i]), cv2.IMREAD_UNCHANGED).astype(np.float64) / 5000.0  # metres
        assert mm.dtype == np.uint16 and mm.shape == SIZE
        np.testing.assert_allclose(mm * 0.001, sensor, atol=0.0006)
    bad = tmp_path / "bad"  # depth read at the wrong scale: an error, and nothing written
    code, _, err = cli(["export", "nerfstudio", str(run), "--out", str(bad), "--depth-scale", "1000"], capsys)
    assert code == 2 and "--depth-scale" in err and "Traceback" not in err
    assert not bad.exists() and not list(tmp_path.glob(".*"))


def test_distortion_gives_an_opencv_camera(mono, tmp_path, capsys):
    _, run = mono
    fx, fy, cx, cy = calib_values(run)[:4]
    dist = [-0.05, 0.01, 0.001, -0.002]
    bent = with_calibration(run, tmp_path / "run", [fx, fy, cx, cy, *dist])
    out = tmp_path / "ns"
    code, _, err = cli(["export", "nerfstudio", str(bent), "--out", str(out), "--quiet"], capsys)
    assert code == 0, err
    doc = json.loads((out / "transforms.json").read_text())
    assert doc["camera_model"] == "OPENCV"
    assert [doc[k] for k in ("k1", "k2", "p1", "p2")] == dist


def test_masks_follow_the_distortion():
    """A raw (distorted) input pixel takes the grid cell its undistorted position falls in."""
    from droidw_cli.export.trainer_masks import grid_lookup
    from droidw_cli.io.calibration import Calibration

    calib = Calibration(250.0, 250.0, 161.0, 118.0, (-0.2, 0.05, 0.002, -0.001))
    work = calib.prepared(SIZE, 19200).as_array()
    lookup = grid_lookup(calib, SIZE, work, (15, 20))
    rows, cols = (a.ravel() for a in np.mgrid[1:14, 1:19])
    x = ((8 * cols + 3.5) - work[2]) / work[0]  # cell centres, normalised
    y = ((8 * rows + 3.5) - work[3]) / work[1]
    raw, _ = cv2.projectPoints(np.stack([x, y, np.ones_like(x)], -1), np.zeros(3), np.zeros(3), calib.camera_matrix(),
                               np.array(calib.distortion))
    u, v = np.rint(raw.reshape(-1, 2)).astype(int).T
    assert np.abs(raw.reshape(-1, 2) - np.stack([(x * calib.fx + calib.cx), (y * calib.fy + calib.cy)], -1)).max() > 3
    np.testing.assert_array_equal(lookup.rows[v, u], rows)
    np.testing.assert_array_equal(lookup.cols[v, u], cols)


@pytest.mark.filterwarnings("ignore:.*cannot decode the image")  # the removed frame, skipped by the source
def test_errors_are_one_line_and_write_nothing(mono, tmp_path, capsys):
    seq, run = mono
    out = tmp_path / "out"
    code, _, err = cli(["export", "nerfstudio", str(tmp_path / "nowhere"), "--out", str(out)], capsys)
    assert code == 2 and "no such run folder" in err and not out.exists()
    taken = tmp_path / "taken"
    taken.mkdir()
    (taken / "keep.txt").write_text("mine")
    code, _, err = cli(["export", "nerfstudio", str(run), "--out", str(taken)], capsys)
    assert code == 2 and "not empty" in err and sorted(p.name for p in taken.iterdir()) == ["keep.txt"]
    gone = with_input(run, tmp_path / "gone", str(tmp_path / "moved-away"))
    code, _, err = cli(["export", "nerfstudio", str(gone), "--out", str(out)], capsys)
    assert code == 2 and "--input" in err and "Traceback" not in err and not out.exists()
    moved = tmp_path / "moved"
    shutil.copytree(seq, moved)
    last = int(run_arrays(run)["index"][-1])
    listing(moved, "rgb")[last].unlink()  # the last keyframe's frame is gone: found only after the others were written
    code, _, err = cli(["export", "nerfstudio", str(gone), "--out", str(out), "--input", str(moved)], capsys)
    assert code == 2 and f"frame {last} " in err and "missing" in err and "Traceback" not in err, err
    assert not out.exists() and not list(tmp_path.glob(".*"))  # nothing partial
    empty = tmp_path / "empty-run"
    empty.mkdir()
    np.savez(empty / "keyframes.npz", poses_c2w=np.zeros((0, 4, 4)), index=np.zeros(0, np.int64))
    shutil.copy(run / "run.json", empty / "run.json")
    code, _, err = cli(["export", "nerfstudio", str(empty), "--out", str(out)], capsys)
    assert code == 2 and "no keyframes" in err and not out.exists()


def test_input_option_finds_moved_frames(mono, tmp_path, capsys):
    seq, run = mono
    moved = tmp_path / "moved"
    shutil.copytree(seq, moved)
    gone = with_input(run, tmp_path / "gone", str(tmp_path / "moved-away"))
    out = tmp_path / "out"
    code, stdout, err = cli(["export", "nerfstudio", str(gone), "--out", str(out), "--input", str(moved)], capsys)
    assert code == 0, err
    assert stdout.startswith(f"wrote {len(run_arrays(run)['index'])} frames")
