"""`droidw export render`: a point cloud drawn into a PNG from a virtual camera."""

import cv2
import numpy as np
import pytest

from cli_run import run
from droidw_cli.export.render import RenderParams, View, look_at, rasterise, render_cloud, scene_axes
from droidw_cli.geometry.camera import BA_SCALE, unscale_intrinsics


def _run_npz(num_kf=5, h=12, w=16):
    """Keyframes sliding along x in front of a textured plane at z = 2 m (uncertainty low everywhere)."""
    rng = np.random.default_rng(0)
    poses = np.tile(np.eye(4), (num_kf, 1, 1))
    poses[:, 0, 3] = 0.05 * np.arange(num_kf)
    return {
        "index": np.arange(num_kf) * 3, "timestamps": np.arange(num_kf) * 0.1, "poses_c2w": poses,
        "disps": np.full((num_kf, h, w), 0.5, np.float32),
        "intrinsics": unscale_intrinsics(np.array([12.0, 12.0, (w - 1) / 2, (h - 1) / 2]), BA_SCALE),
        "work_size": np.array([h * BA_SCALE, w * BA_SCALE]),
        "images": rng.integers(60, 255, (num_kf, h * 2, w * 2, 3), dtype=np.uint8),
        "uncertainty": np.full((num_kf, h, w), 0.3, np.float32),
    }


def test_render_command_writes_a_png_of_the_requested_size(tmp_path, capsys):
    (tmp_path / "run").mkdir()
    np.savez(tmp_path / "run" / "keyframes.npz", **_run_npz())
    out = tmp_path / "cloud.png"
    code, stdout, err = run(["export", "render", str(tmp_path / "run"), "--out", str(out), "--size", "320x200"], capsys)
    assert code == 0, err
    assert "rendered" in stdout and out.is_file()
    image = cv2.imread(str(out), cv2.IMREAD_COLOR)
    assert image.shape == (200, 320, 3)
    background = np.array(RenderParams().background[::-1])  # BGR on disk
    drawn = np.any(image != background, axis=-1)
    assert 0.02 < drawn.mean() < 0.95  # 912 static points of 2×2 px: part of the view, not none, not all
    ys, xs = np.nonzero(drawn)
    assert xs.max() - xs.min() > 0.3 * 320 and ys.max() - ys.min() > 0.2 * 200  # the view frames the cloud
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50  # the texture's colours, not one flat fill
    assert not list(tmp_path.glob(".*tmp"))


def test_render_command_errors_are_one_line(tmp_path, capsys):
    code, _, err = run(["export", "render", str(tmp_path / "missing"), "--out", str(tmp_path / "x.png")], capsys)
    assert code == 2 and "no such file" in err
    (tmp_path / "run").mkdir()
    np.savez(tmp_path / "run" / "keyframes.npz", **_run_npz())
    code, _, err = run(["export", "render", str(tmp_path / "run"), "--size", "big"], capsys)
    assert code == 2 and "WIDTHxHEIGHT" in err
    code, _, err = run(["export", "render", str(tmp_path / "run"), "--elevation", "95"], capsys)
    assert code == 2 and "elevation" in err
    assert not (tmp_path / "x.png").exists()


def test_nearest_splat_wins_and_far_points_fade():
    params = RenderParams(width=32, height=24, point_size=1, depth_shading=0.5, background=(0, 0, 0))
    uv = np.array([[10.0, 10.0], [10.0, 10.0], [20.0, 5.0], [-5.0, 3.0]])
    z = np.array([2.0, 1.0, 3.0, 1.0])  # two points on one pixel; one outside the image
    rgb = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 200], [255, 255, 255]], np.uint8)
    image = rasterise(uv, z, rgb, params)
    assert tuple(image[10, 10]) == (0, 255, 0)  # the nearer green point hides the red one
    assert tuple(image[5, 20]) == (0, 0, 100)  # the farthest point fades half-way to the background
    assert np.count_nonzero(image.any(-1)) == 2


def test_splats_cover_point_size_squared_pixels():
    params = RenderParams(width=40, height=30, point_size=3, depth_shading=0.0, background=(0, 0, 0))
    image = rasterise(np.array([[20.0, 15.0]]), np.array([1.0]), np.array([[9, 9, 9]], np.uint8), params)
    ys, xs = np.nonzero(image[..., 0])
    assert len(ys) == 9 and (ys.min(), ys.max(), xs.min(), xs.max()) == (14, 16, 19, 21)


def test_orbit_camera_frames_the_cloud_and_keeps_up_up():
    rng = np.random.default_rng(1)
    cube = rng.uniform(-1, 1, (2000, 3)) + np.array([0.0, 0.0, 5.0])
    poses = np.tile(np.eye(4), (3, 1, 1))  # OpenCV cameras: up is world −y
    up, ahead = scene_axes(poses)
    np.testing.assert_allclose(up, [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(ahead, [0, 0, 1], atol=1e-12)
    for azimuth, elevation in ((0, 25), (90, 10), (200, 60)):
        params = RenderParams(width=64, height=48, azimuth=azimuth, elevation=elevation)
        view = look_at(cube, poses, params)
        uv, z = view.project(cube)
        assert np.all(z > 0)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] <= 63) & (uv[:, 1] >= 0) & (uv[:, 1] <= 47)
        assert inside.mean() > 0.95
        # a point above the cloud's centre (world −y) appears higher in the image (smaller v) than one below
        pair, _ = view.project(np.array([[0.0, -1.0, 5.0], [0.0, 1.0, 5.0]]))
        assert pair[0, 1] < pair[1, 1]


def test_view_projection_matches_a_pinhole():
    view = View(np.eye(3), np.zeros(3), 100.0, 201, 101)
    uv, z = view.project(np.array([[0.0, 0.0, 2.0], [1.0, -0.5, 2.0]]))
    np.testing.assert_allclose(uv, [[100.0, 50.0], [150.0, 25.0]])
    np.testing.assert_allclose(z, [2.0, 2.0])


def test_dynamic_points_get_the_dynamic_colour_and_trajectory_is_drawn():
    xyz = np.stack(np.meshgrid(np.linspace(-1, 1, 40), np.linspace(-1, 1, 40), [4.0]), -1).reshape(-1, 3)
    rgb = np.full((len(xyz), 3), 100, np.uint8)
    dynamic = xyz[:, 0] > 0.5
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, 0, 3] = np.linspace(-0.5, 0.5, 4)
    params = RenderParams(width=120, height=90, depth_shading=0.0)
    plain = render_cloud(xyz, rgb, poses, params, trajectory=False)
    marked = render_cloud(xyz, rgb, poses, params, dynamic=dynamic)
    assert np.any(np.all(marked == params.dynamic_colour, axis=-1))
    assert not np.any(np.all(plain == params.dynamic_colour, axis=-1))
    near_path = np.abs(marked.astype(int) - params.trajectory_colour).max(-1) < 40  # anti-aliased line
    assert near_path.sum() > 20 and not np.any(np.abs(plain.astype(int) - params.trajectory_colour).max(-1) < 40)
    with pytest.raises(ValueError, match="no points"):
        render_cloud(np.zeros((0, 3)), np.zeros((0, 3), np.uint8), poses, params)


def test_render_of_a_single_keyframe_run_fails_cleanly(tmp_path, capsys):
    (tmp_path / "run").mkdir()
    np.savez(tmp_path / "run" / "keyframes.npz", **_run_npz(num_kf=1))
    out = tmp_path / "cloud.png"
    for what in ("static", "all"):
        code, _, err = run(["export", "render", str(tmp_path / "run"), "--what", what, "--out", str(out)], capsys)
        assert code == 2, err
        assert err.startswith("droidw: error:") and "1 keyframe" in err and "Traceback" not in err
        assert not out.exists() and not list(tmp_path.glob(".*tmp"))
    code, stdout, err = run(["export", "render", str(tmp_path / "run"), "--min-views", "0", "--out", str(out)], capsys)
    assert code == 0 and "rendered 192 points" in stdout and out.is_file(), err


def _count(stdout: str) -> int:
    """The point count of `wrote N points ...` / `rendered N points ...`."""
    return int(stdout.split()[1])


def test_render_draws_the_points_export_ply_writes(tmp_path, capsys):
    """`render --what X` draws exactly the points of `ply --what X`: not the rejected ones, and only the
    dynamic ones in the dynamic colour."""
    npz = _run_npz()
    npz["images"][:] = 128  # grey: any red pixel is the dynamic colour
    npz["uncertainty"][2, 1:5, 1:5] = 30.0  # rejected for uncertainty: neither static nor dynamic
    dynamic = np.zeros(npz["disps"].shape, bool)
    dynamic[1, 6:10, 10:14] = True  # masked dynamic
    npz.update(dynamic=dynamic, object_ids=np.where(dynamic, 4, -1).astype(np.int32), masked=dynamic.copy())
    (tmp_path / "run").mkdir()
    np.savez(tmp_path / "run" / "keyframes.npz", **npz)
    for what in ("static", "all"):
        code, out_ply, err = run(["export", "ply", str(tmp_path / "run"), "--what", what,
                                  "--out", str(tmp_path / f"{what}.ply")], capsys)
        assert code == 0, err
        code, out_png, err = run(["export", "render", str(tmp_path / "run"), "--what", what, "--no-trajectory",
                                  "--point-size", "1", "--out", str(tmp_path / f"{what}.png")], capsys)
        assert code == 0, err
        assert _count(out_png) == _count(out_ply)
    # all = 880 static + 16 dynamic: not the uncertain block (16) nor the 4 × 12 edge-column points that
    # leave the neighbours' views (too few views)
    assert _count(out_ply) == 5 * 12 * 16 - 16 - 4 * 12
    red = RenderParams().dynamic_colour
    image = cv2.cvtColor(cv2.imread(str(tmp_path / "all.png")), cv2.COLOR_BGR2RGB).astype(int)
    reddish = (image[..., 0] > image[..., 1] + 40) & (image[..., 0] > image[..., 2] + 40)
    assert 0 < reddish.sum() <= 16  # the 16 dynamic points (1 px splats), not the 16 rejected ones too
    assert np.abs(image[reddish] - red).max() < 120  # faded towards the background at most
