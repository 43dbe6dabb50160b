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
