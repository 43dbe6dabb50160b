"""PLY export: multi-view agreement, static/dynamic split, readable files."""

import numpy as np
import pytest

from droidw_cli.export.pointcloud import CloudParams, build_cloud, multiview_support, write_ply
from droidw_cli.geometry.camera import BA_SCALE, unscale_intrinsics


def _plane_run(num_kf=5, h=12, w=16, mover=True):
    """Keyframes translating along x, looking at a fronto-parallel plane at z = 2 m."""
    k8 = np.array([12.0, 12.0, (w - 1) / 2, (h - 1) / 2])
    poses = np.tile(np.eye(4), (num_kf, 1, 1))
    poses[:, 0, 3] = 0.05 * np.arange(num_kf)
    disps = np.full((num_kf, h, w), 0.5, np.float32)
    unc = np.full((num_kf, h, w), 0.3, np.float32)
    if mover:  # a block that floats at 1 m in keyframe 2 only: no neighbour agrees with it
        disps[2, 4:8, 6:10] = 1.0
        unc[2, 4:8, 6:10] = 2.0
    return {
        "disps": disps, "poses_c2w": poses, "intrinsics": unscale_intrinsics(k8, BA_SCALE),
        "images": np.full((num_kf, h * 2, w * 2, 3), 128, np.uint8), "timestamps": np.arange(num_kf) * 0.1,
        "uncertainty": unc,
    }


def test_multiview_support_counts_agreeing_neighbours():
    run = _plane_run()
    k8 = np.array([12.0, 12.0, 7.5, 5.5])
    support = multiview_support(run["disps"], run["poses_c2w"], k8, radius=2, rel_tol=0.05)
    assert support[2, 5, 7] == 0  # the floating block: nobody agrees
    assert support[2, 6, 3] >= 3  # plane pixels of the middle keyframe agree with ≥ 3 of 4 neighbours
    assert support[0, 6, 12] >= 1


def test_static_cloud_excludes_mover_and_ply_is_readable(tmp_path):
    plyfile = pytest.importorskip("plyfile")
    cloud = build_cloud(_plane_run(), CloudParams())
    static = cloud.select(cloud.static)
    dynamic = cloud.select(~cloud.static)
    assert len(static.xyz) > 0
    assert np.all(np.abs(static.xyz[:, 2] - 2.0) < 1e-3)  # only plane points
    assert np.any(np.abs(dynamic.xyz[:, 2] - 1.0) < 1e-3)  # the block is dynamic
    n = write_ply(tmp_path / "static.ply", static, with_time=False)
    m = write_ply(tmp_path / "dynamic.ply", dynamic, with_time=True)
    data = plyfile.PlyData.read(str(tmp_path / "static.ply"))
    assert data["vertex"].count == n == len(static.xyz)
    np.testing.assert_allclose(data["vertex"]["z"], static.xyz[:, 2])
    dyn = plyfile.PlyData.read(str(tmp_path / "dynamic.ply"))
    assert dyn["vertex"].count == m
    assert set(np.unique(dyn["vertex"]["t"])) <= {0.0, 0.1, 0.2, 0.30000000000000004, 0.4}


def test_stride_and_no_partial_file(tmp_path):
    full = build_cloud(_plane_run(mover=False), CloudParams(stride=1))
    half = build_cloud(_plane_run(mover=False), CloudParams(stride=2))
    assert len(half.xyz) == 3 * 12 * 16 and len(full.xyz) == 5 * 12 * 16
    target = tmp_path / "sub" / "x.ply"
    write_ply(target, full, with_time=False)
    assert target.is_file() and not list(target.parent.glob(".*tmp"))


def test_static_points_keep_a_margin_from_the_dynamic_mask():
    run = _plane_run(mover=False)
    dynamic = np.zeros(run["disps"].shape, bool)
    dynamic[2, 4:8, 6:10] = True
    run["dynamic"] = dynamic
    run["object_ids"] = np.where(dynamic, 0, -1).astype(np.int32)
    plain = build_cloud(run, CloudParams(dynamic_margin=0)).static.reshape(dynamic.shape)
    margin = build_cloud(run, CloudParams(dynamic_margin=1)).static.reshape(dynamic.shape)
    assert not plain[2, 4:8, 6:10].any() and not margin[2, 4:8, 6:10].any()
    assert plain[2, 3, 6:10].all() and plain[2, 4:8, 10].all()  # the ring next to the mask
    assert not margin[2, 3, 5:11].any() and not margin[2, 4:8, 10].any()
    assert margin[2, 2, 6:10].all() and margin[2, 4:8, 11].all()  # two cells away: static again
    assert margin[1].sum() == plain[1].sum()  # other keyframes untouched


def test_static_cloud_leaves_out_the_pixels_ba_zeroed():
    run = _plane_run(mover=False)
    dynamic = np.zeros(run["disps"].shape, bool)
    run["dynamic"] = dynamic
    run["object_ids"] = np.full(dynamic.shape, -1, np.int32)
    masked = dynamic.copy()
    masked[3, 5:7, 5:7] = True  # zeroed in the loop, not in the output mask
    run["masked"] = masked
    static = build_cloud(run, CloudParams(dynamic_margin=0)).static.reshape(dynamic.shape)
    assert not static[3, 5:7, 5:7].any() and static[3, 4, 5:7].all()
    cloud = build_cloud(run, CloudParams(dynamic_margin=0))
    assert not cloud.dynamic.any()  # the output mask stays what it was
    grown = build_cloud(run, CloudParams(dynamic_margin=1)).static.reshape(dynamic.shape)  # the margin grows 'masked' too
    assert not grown[3, 4:8, 4:8].any() and grown[3, 3, 5:7].all()


def _save_run(folder, npz, num_kf):
    """``npz`` as a run folder's keyframes.npz, with the keys `droidw view` also needs."""
    folder.mkdir()
    h, w = npz["disps"].shape[1:]
    np.savez(folder / "keyframes.npz", index=np.arange(num_kf) * 3, work_size=np.array([h * BA_SCALE, w * BA_SCALE]),
             **npz)
    return folder


def test_multiview_support_with_fewer_keyframes_than_the_radius():
    k8 = np.array([12.0, 12.0, 7.5, 5.5])
    for num_kf in (1, 2):  # radius 2 reaches past both ends: used to raise in torch.arange
        plane = _plane_run(num_kf=num_kf, mover=False)
        support = multiview_support(plane["disps"], plane["poses_c2w"], k8, radius=2, rel_tol=0.05)
        assert support.shape == (num_kf, 12, 16)
        assert support.max() == num_kf - 1  # one keyframe: no neighbour; two: each other


def test_too_few_keyframes_for_min_views_is_a_user_error():
    from droidw_cli.errors import InputError

    one = _plane_run(num_kf=1, mover=False)
    with pytest.raises(InputError, match=r"1 keyframe.*--min-views 2"):
        build_cloud(one, CloudParams())
    with pytest.raises(InputError, match=r"2 keyframes.*--min-views 2"):
        build_cloud(_plane_run(num_kf=2, mover=False), CloudParams())  # at most 1 neighbour can agree
    with pytest.raises(InputError, match=r"--min-views 5.*at most 4"):
        build_cloud(_plane_run(), CloudParams(min_views=5))  # radius 2: 4 neighbours whatever the run's length
    unchecked = build_cloud(one, CloudParams(min_views=0))  # asked for explicitly: the depth without the test
    assert len(unchecked.xyz) == 12 * 16 and unchecked.static.all()
    assert build_cloud(_plane_run(num_kf=2, mover=False), CloudParams(min_views=1)).static.sum() > 0


@pytest.mark.parametrize("what", ["static", "dynamic", "all"])
def test_export_ply_of_a_single_keyframe_run_fails_cleanly(tmp_path, capsys, what):
    from cli_run import run

    one = _plane_run(num_kf=1, mover=False)
    one["dynamic"] = np.zeros(one["disps"].shape, bool)
    one["object_ids"] = np.full(one["disps"].shape, -1, np.int32)
    folder = _save_run(tmp_path / "run", one, 1)
    out = tmp_path / "out.ply"
    code, stdout, err = run(["export", "ply", str(folder), "--what", what, "--out", str(out)], capsys)
    assert code == 2, err
    assert err.startswith("droidw: error:") and "1 keyframe" in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".*tmp"))  # no file, not even a partial one
    code, stdout, err = run(["export", "ply", str(folder), "--what", what, "--min-views", "0", "--out", str(out)],
                            capsys)
    assert code == 0, err
    assert stdout.startswith(f"wrote {0 if what == 'dynamic' else 12 * 16} points")


def test_export_ply_of_a_run_without_keyframes_fails_cleanly(tmp_path, capsys):
    from cli_run import run

    empty = {k: v[:0] for k, v in _plane_run(num_kf=1, mover=False).items() if k in ("disps", "poses_c2w")}
    empty.update(intrinsics=_plane_run(num_kf=1, mover=False)["intrinsics"])
    folder = _save_run(tmp_path / "run", empty, 0)
    code, stdout, err = run(["export", "ply", str(folder), "--out", str(tmp_path / "out.ply")], capsys)
    assert code == 2 and "no keyframes" in err and "Traceback" not in err, err
