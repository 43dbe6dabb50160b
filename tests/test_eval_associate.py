"""Timestamp association: hand-made cases and evo's matching rule on random stamps."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.errors import InputError
from droidw_cli.eval.associate import AssociationError, associate, associate_by_index, nearest_matches
from droidw_cli.io.trajectory import Trajectory


def traj(stamps) -> Trajectory:
    stamps = np.asarray(stamps, dtype=float)
    poses = np.tile(np.eye(4), (stamps.size, 1, 1))
    poses[:, 0, 3] = np.arange(stamps.size)  # position x = own index, to identify poses
    return Trajectory(stamps, poses)


def test_nearest_within_max_diff_and_ties_go_to_the_earlier_pose():
    long_ = np.array([0.0, 1.0, 2.0, 3.0])
    short = np.array([0.5, 1.02, 1.98, 3.5, -0.2, 2.9])
    i_s, i_l = nearest_matches(short, long_, max_diff=0.5)
    # 0.5 is equidistant from 0.0 and 1.0 -> 0.0; 3.5 is 0.5 past the end -> 3.0; -0.2 -> 0.0
    assert i_s.tolist() == [0, 1, 2, 3, 4, 5]
    assert i_l.tolist() == [0, 1, 2, 3, 0, 3]
    i_s, i_l = nearest_matches(short, long_, max_diff=0.05)
    assert i_s.tolist() == [1, 2]
    assert i_l.tolist() == [1, 2]


def test_shorter_trajectory_drives_and_offset_shifts_the_estimate():
    gt = traj(np.arange(0.0, 2.0, 0.01))  # 200 poses at 100 Hz
    est = traj(np.arange(0.0, 1.0, 0.1) + 0.5)  # 10 poses, shifted by +0.5 s
    a = associate(gt, est, max_diff=0.004)
    np.testing.assert_allclose(gt.timestamps[a.gt_index], est.timestamps[a.est_index], atol=1e-9)
    assert a.est_index.tolist() == list(range(10))
    b = associate(gt, est, max_diff=0.004, offset=-0.5)  # est time + offset = gt time
    np.testing.assert_allclose(gt.timestamps[b.gt_index], est.timestamps[b.est_index] - 0.5, atol=1e-9)
    # the estimate longer than the ground truth: the ground truth drives
    c = associate(est, gt, max_diff=0.004)
    assert c.gt_index.tolist() == list(range(10))
    np.testing.assert_allclose(est.timestamps[c.gt_index], gt.timestamps[c.est_index], atol=1e-9)


def test_no_overlap_is_a_clear_input_error():
    with pytest.raises(AssociationError, match="no overlapping timestamps") as info:
        associate(traj([0.0, 1.0, 2.0]), traj([10.0, 11.0, 12.0]), max_diff=0.02)
    assert isinstance(info.value, InputError)
    assert "\n" not in str(info.value)


def test_unsorted_stamps_use_the_nearest_neighbour():
    long_ = np.array([3.0, 1.0, 2.0, 0.0])
    i_s, i_l = nearest_matches(np.array([0.01, 2.02, 5.0]), long_, max_diff=0.05)
    assert i_s.tolist() == [0, 1]
    assert i_l.tolist() == [3, 2]


def test_by_index_pairs_equal_lengths_only():
    a = associate_by_index(traj(np.arange(5.0)), traj(np.arange(5.0)))
    assert a.gt_index.tolist() == a.est_index.tolist() == [0, 1, 2, 3, 4]
    with pytest.raises(AssociationError, match="by index"):
        associate_by_index(traj(np.arange(5.0)), traj(np.arange(4.0)))


def random_stamps(rng, n, rate, jitter, drop, t0=1.3e9, dup=0.0):
    t = t0 + np.arange(n) / rate + rng.uniform(-jitter, jitter, size=n)
    t = np.sort(t)[rng.uniform(size=n) > drop]
    if dup:
        rep = np.flatnonzero(rng.uniform(size=t.size) < dup)
        t = np.sort(np.concatenate([t, t[rep]]))
    return t


@pytest.mark.parametrize("seed", range(6))
def test_same_pairs_as_evo(seed):
    sync = pytest.importorskip("evo.core.sync")
    from evo.core.trajectory import PoseTrajectory3D

    rng = np.random.default_rng(seed)
    gt_t = random_stamps(rng, 600, 100.0, 0.002, 0.05)
    est_t = random_stamps(rng, 200, 30.0, 0.01, 0.1, t0=1.3e9 + rng.uniform(-0.5, 0.5), dup=0.03)
    if seed % 2:
        gt_t, est_t = est_t, gt_t  # also the estimate longer than the ground truth
    max_diff = [0.0, 0.005, 0.01, 0.02, 0.05, 1.0][seed]
    offset = [0.0, 0.01, -0.02, 0.0, 0.3, 0.0][seed]
    gt, est = traj(gt_t), traj(est_t)

    def evo_traj(t):
        return PoseTrajectory3D(poses_se3=list(np.tile(np.eye(4), (t.size, 1, 1)) + 0.0), timestamps=t)

    try:
        r, e = sync.associate_trajectories(evo_traj(gt_t), evo_traj(est_t), max_diff=max_diff, offset_2=offset)
    except sync.SyncException:
        with pytest.raises(AssociationError):
            associate(gt, est, max_diff, offset)
        return
    ours = associate(gt, est, max_diff, offset)
    np.testing.assert_array_equal(gt.timestamps[ours.gt_index], r.timestamps)
    np.testing.assert_array_equal(est.timestamps[ours.est_index], e.timestamps)


@pytest.mark.parametrize("seed", range(4))
def test_matching_indices_identical_to_evo_including_unsorted(seed):
    sync = pytest.importorskip("evo.core.sync")
    rng = np.random.default_rng(100 + seed)
    a = np.round(rng.uniform(0, 10, size=300), 3)
    b = np.round(rng.uniform(0, 10, size=500), 3)  # rounding makes exact ties likely
    if seed < 2:
        b = np.sort(b)
    ref = sync.matching_time_indices(a, b, max_diff=0.01 * (seed + 1), offset_2=0.001 * seed)
    ours = nearest_matches(a, b, 0.01 * (seed + 1), 0.001 * seed)
    assert ours[0].tolist() == ref[0]
    assert ours[1].tolist() == ref[1]
