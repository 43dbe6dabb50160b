"""Agreement with evo on the real trajectories of ../shared/data/trajectories/evo (skipped without it)."""

from __future__ import annotations

import copy
from functools import lru_cache
from pathlib import Path

import pytest

from droidw_cli.cli import main
from droidw_cli.eval import evaluate_ate, evaluate_rpe
from droidw_cli.io.trajectory import read_kitti, read_trajectory

REL = 1e-6

PAIRS = [
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam.txt"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-ORB_kf_mono.txt"),
    ("freiburg1_xyz-groundtruth.txt", "freiburg1_xyz-rgbdslam_drift.txt"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB.txt"),
    ("fr2_desk_groundtruth.txt", "fr2_desk_ORB_kf_mono.txt"),
    ("KITTI_00_gt.txt", "KITTI_00_ORB.txt"),
    ("V102_groundtruth.csv", "V102.txt"),
]


@lru_cache(maxsize=None)
def ours(path: str):
    return read_trajectory(path)


@lru_cache(maxsize=None)
def evo_read(path: str):
    from evo.tools import file_interface

    if path.endswith(".csv"):
        return file_interface.read_euroc_csv_trajectory(path)
    if "KITTI" in path:
        return file_interface.read_kitti_poses_file(path)
    return file_interface.read_tum_trajectory_file(path)


def evo_eval(gt_path: str, est_path: str, align: str, max_diff: float, rpe_delta: int):
    sync = pytest.importorskip("evo.core.sync")
    from evo.core import metrics

    ref, est = evo_read(gt_path), evo_read(est_path)
    if "KITTI" not in gt_path:
        ref, est = sync.associate_trajectories(ref, est, max_diff=max_diff)
    est = copy.deepcopy(est)
    _, _, scale = est.align(ref, correct_scale=align == "sim3")
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, rpe_delta, metrics.Unit.frames)
    rpe.process_data((ref, est))
    return ape.get_all_statistics(), scale, est.num_poses, rpe.get_all_statistics()


@pytest.mark.shared
@pytest.mark.parametrize("align", ["sim3", "se3"])
@pytest.mark.parametrize("gt_name,est_name", PAIRS)
def test_agrees_with_evo_on_real_pairs(shared_data, gt_name, est_name, align):
    pytest.importorskip("evo")
    folder = shared_data / "trajectories" / "evo"
    gt_path, est_path = str(folder / gt_name), str(folder / est_name)
    by_index = "KITTI" in gt_name
    max_diff = 0.02
    res = evaluate_ate(ours(gt_path), ours(est_path), align, max_diff, by_index=by_index)
    stats, scale, n, rpe = evo_eval(gt_path, est_path, align, max_diff, rpe_delta=5)
    assert res.matches == n
    for key in ("rmse", "mean", "median", "max", "std"):
        assert getattr(res, key) == pytest.approx(stats[key], rel=REL), key
    assert res.scale == pytest.approx(scale, rel=REL)
    ours_rpe = evaluate_rpe(ours(gt_path), ours(est_path), res, 5)
    assert ours_rpe.stats.rmse == pytest.approx(rpe["rmse"], rel=REL)


@pytest.mark.shared
def test_reference_figure_fr1_xyz_rgbdslam(shared_data):
    # evo_ape tum freiburg1_xyz-groundtruth.txt freiburg1_xyz-rgbdslam.txt -as  (evo's default max_diff 0.01)
    folder = shared_data / "trajectories" / "evo"
    res = evaluate_ate(read_trajectory(folder / "freiburg1_xyz-groundtruth.txt"),
                       read_trajectory(folder / "freiburg1_xyz-rgbdslam.txt"), "sim3", max_diff=0.01)
    assert res.rmse == pytest.approx(0.013389, abs=5e-7)


@pytest.mark.shared
def test_kitti_with_times_file_matches_by_index(shared_data):
    folder = shared_data / "trajectories" / "evo"
    gt = read_kitti(folder / "KITTI_00_gt.txt", folder / "KITTI_00_gt_times.txt")
    est = read_kitti(folder / "KITTI_00_ORB.txt", folder / "KITTI_00_gt_times.txt")
    by_time = evaluate_ate(gt, est, "sim3", 0.02)
    by_index = evaluate_ate(read_trajectory(folder / "KITTI_00_gt.txt"), read_trajectory(folder / "KITTI_00_ORB.txt"),
                            "sim3", by_index=True)
    assert by_time.matches == by_index.matches == len(gt)
    assert by_time.rmse == pytest.approx(by_index.rmse, rel=1e-12)


@pytest.mark.shared
def test_cli_on_euroc_ground_truth(shared_data, capsys):
    import json

    folder: Path = shared_data / "trajectories" / "evo"
    main(["eval", "--gt", str(folder / "V102_groundtruth.csv"), "--est", str(folder / "V102.txt"), "--json"])
    out = json.loads(capsys.readouterr().out)
    stats, scale, n, _ = evo_eval(str(folder / "V102_groundtruth.csv"), str(folder / "V102.txt"), "sim3", 0.02, 1)
    assert out["matches"] == n
    assert out["ate"]["rmse"] == pytest.approx(stats["rmse"], rel=REL)
    assert out["scale"] == pytest.approx(scale, rel=REL)
