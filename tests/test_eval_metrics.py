"""ATE / RPE on synthetic trajectories: known Sim(3) recovered, evo agrees, clear errors."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from droidw_cli.eval import (
    AssociationError,
    AteResult,
    DegenerateGeometryError,
    ErrorStats,
    TooFewMatchesError,
    evaluate_ate,
    evaluate_rpe,
)
from droidw_cli.eval.metrics import relative_errors
from droidw_cli.io.trajectory import Trajectory

REL = 1e-6  # the acceptance tolerance against evo


def rodrigues(w: np.ndarray) -> np.ndarray:
    """(N, 3) rotation vectors → (N, 3, 3) matrices."""
    theta = np.linalg.norm(w, axis=1)[:, None, None]
    k = w / np.maximum(theta[:, :, 0], 1e-12)
    kx = np.zeros((len(w), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    kx = kx - np.swapaxes(kx, 1, 2)
    return np.eye(3) + np.sin(theta) * kx + (1 - np.cos(theta)) * kx @ kx


def smooth_trajectory(seed: int, n: int = 300, rate: float = 30.0, t0: float = 1305031102.0) -> Trajectory:
    """A random smooth 3D camera path: sums of slow sinusoids for position and rotation vector."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate
    freq = rng.uniform(0.05, 0.4, size=(3, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(3, 3))
    amp = rng.uniform(0.3, 1.5, size=(3, 3))
    pos = np.stack([(amp[d] * np.sin(2 * np.pi * freq[d] * t[:, None] + phase[d])).sum(1) for d in range(3)], 1)
    rotvec = 0.4 * np.sin(2 * np.pi * 0.1 * t[:, None] + rng.uniform(0, 6, size=3))
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, :3, :3] = rodrigues(rotvec)
    poses[:, :3, 3] = pos
    return Trajectory(t0 + t, poses)


def transformed(gt: Trajectory, r: np.ndarray, t: np.ndarray, s: float, noise: float, seed: int,
                time_jitter: float = 0.0) -> Trajectory:
    """The estimate a SLAM system would give in its own frame: gt mapped by x ↦ s R x + t, plus noise."""
    rng = np.random.default_rng(seed)
    poses = gt.poses.copy()
    poses[:, :3, :3] = r @ gt.poses[:, :3, :3]
    poses[:, :3, 3] = s * gt.positions @ r.T + t + rng.normal(scale=noise, size=gt.positions.shape)
    stamps = gt.timestamps + rng.uniform(-time_jitter, time_jitter, size=len(gt))
    return Trajectory(stamps, poses)


R0 = rodrigues(np.array([[0.3, -0.8, 1.2]]))[0]
T0 = np.array([2.0, -1.0, 0.5])
S0 = 0.37


def test_known_sim3_is_recovered_exactly_without_noise():
    gt = smooth_trajectory(1)
    est = transformed(gt, R0, T0, S0, noise=0.0, seed=1)
    res = evaluate_ate(gt, est, "sim3")
    assert res.matches == len(gt)
    assert res.scale == pytest.approx(1 / S0, rel=1e-10)
    np.testing.assert_allclose(res.rotation, R0.T, atol=1e-10)
    np.testing.assert_allclose(res.translation, -R0.T @ T0 / S0, atol=1e-9)
    assert res.rmse < 1e-9
    assert res.max < 1e-9


def test_noise_level_and_scale_with_noise():
    gt = smooth_trajectory(2, n=600)
    est = transformed(gt, R0, T0, S0, noise=0.002, seed=2)
    res = evaluate_ate(gt, est, "sim3")
    # isotropic noise σ in the estimate's frame is σ/s in metres; ATE ≈ sqrt(3) σ / s
    assert res.rmse == pytest.approx(np.sqrt(3) * 0.002 / S0, rel=0.1)
    assert res.scale == pytest.approx(1 / S0, rel=2e-3)
    assert np.abs(res.rotation - R0.T).max() < 5e-3
    se3 = evaluate_ate(gt, est, "se3")
    assert se3.scale == 1.0
    assert se3.rmse > 10 * res.rmse  # a wrong scale cannot be aligned away by SE(3)
    assert res.min <= res.median <= res.max
    assert res.stats.count == res.matches == res.positions.shape[0] == res.gt_positions.shape[0]


def test_result_is_frozen_and_deterministic():
    gt = smooth_trajectory(3)
    est = transformed(gt, R0, T0, S0, noise=0.01, seed=3)
    a, b = evaluate_ate(gt, est), evaluate_ate(gt, est)
    assert a.rmse == b.rmse and a.scale == b.scale
    np.testing.assert_array_equal(a.positions, b.positions)
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.rmse = 0.0  # type: ignore[misc]
    assert isinstance(a, AteResult)


def test_error_stats_on_a_known_vector():
    s = ErrorStats.from_errors(np.array([3.0, 4.0, 0.0, 5.0]))
    assert s.rmse == pytest.approx(np.sqrt(50 / 4))
    assert (s.mean, s.median, s.max, s.min, s.count) == (3.0, 3.5, 5.0, 0.0, 4)
    assert s.std == pytest.approx(np.sqrt(((0.0) + 1 + 9 + 4) / 4))


def evo_numbers(gt: Trajectory, est: Trajectory, align: str, max_diff: float, rpe_delta: int = 0):
    """ATE stats and scale (and RPE rmse) computed by evo's python API."""
    sync = pytest.importorskip("evo.core.sync")
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    ref = PoseTrajectory3D(poses_se3=list(gt.poses), timestamps=gt.timestamps.copy())
    e = PoseTrajectory3D(poses_se3=list(est.poses), timestamps=est.timestamps.copy())
    ref, e = sync.associate_trajectories(ref, e, max_diff=max_diff)
    e = copy.deepcopy(e)
    scale = 1.0
    if align != "none":
        _, _, scale = e.align(ref, correct_scale=align == "sim3")
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, e))
    stats = ape.get_all_statistics()
    rpe = None
    if rpe_delta:
        m = metrics.RPE(metrics.PoseRelation.translation_part, rpe_delta, metrics.Unit.frames)
        m.process_data((ref, e))
        rpe = m.get_all_statistics()
    return stats, scale, e.num_poses, rpe


def assert_matches_evo(res: AteResult, stats, scale, n):
    assert res.matches == n
    for key in ("rmse", "mean", "median", "max", "std"):
        assert getattr(res, key) == pytest.approx(stats[key], rel=REL), key
    assert res.scale == pytest.approx(scale, rel=REL)


@pytest.mark.parametrize("align", ["sim3", "se3", "none"])
@pytest.mark.parametrize("seed", [10, 11])
def test_synthetic_pairs_agree_with_evo(align, seed):
    pytest.importorskip("evo")
    gt = smooth_trajectory(seed, n=500, rate=100.0)
    # a sparser, time-jittered estimate with drop-outs, in its own Sim(3) frame
    est = transformed(gt, R0, T0, S0, noise=0.003, seed=seed, time_jitter=0.004).subset(
        np.flatnonzero(np.random.default_rng(seed).uniform(size=len(gt)) > 0.6))
    res = evaluate_ate(gt, est, align, max_diff=0.01)
    stats, scale, n, rpe = evo_numbers(gt, est, align, 0.01, rpe_delta=3)
    assert_matches_evo(res, stats, scale, n)
    ours_rpe = evaluate_rpe(gt, est, res, 3)
    assert ours_rpe.stats.rmse == pytest.approx(rpe["rmse"], rel=REL)
    assert ours_rpe.stats.max == pytest.approx(rpe["max"], rel=REL)
    if align == "sim3":
        assert res.scale == pytest.approx(1 / S0, rel=0.02)


def test_rpe_is_zero_for_an_exact_sim3_copy_and_counts_pairs():
    gt = smooth_trajectory(4, n=100)
    est = transformed(gt, R0, T0, S0, noise=0.0, seed=4)
    res = evaluate_ate(gt, est)
    rpe = evaluate_rpe(gt, est, res, 10)
    assert rpe.stats.count == 9  # pairs (0,10), (10,20), ..., (80,90)
    assert rpe.stats.rmse < 1e-9
    # a constant position offset on one pose gives exactly that error in the two pairs around it
    poses = gt.poses.copy()
    poses[50, :3, 3] += [0.0, 0.0, 0.1]
    errors = relative_errors(gt.poses, poses, 10)
    assert np.count_nonzero(errors > 1e-9) == 2
    with pytest.raises(TooFewMatchesError, match="delta"):
        evaluate_rpe(gt, est, res, 100)
    with pytest.raises(ValueError):
        relative_errors(gt.poses, poses, 0)


def test_errors_no_overlap_too_few_and_collinear():
    gt = smooth_trajectory(5)
    late = Trajectory(gt.timestamps + 1000.0, gt.poses)
    with pytest.raises(AssociationError, match="no overlapping timestamps"):
        evaluate_ate(gt, late)
    two = gt.subset(np.array([0, 100]))
    with pytest.raises(TooFewMatchesError, match="at least 3"):
        evaluate_ate(gt, two)
    line = gt.poses.copy()
    line[:, :3, 3] = np.outer(np.linspace(0, 1, len(gt)), [1.0, 2.0, 3.0])
    with pytest.raises(DegenerateGeometryError, match="collinear"):
        evaluate_ate(gt, Trajectory(gt.timestamps, line))
    still = gt.poses.copy()
    still[:, :3, 3] = [1.0, 1.0, 1.0]
    with pytest.raises(DegenerateGeometryError, match="identical"):
        evaluate_ate(gt, Trajectory(gt.timestamps, still), "se3")
    # without alignment a static estimate is a valid (bad) answer
    assert evaluate_ate(gt, Trajectory(gt.timestamps, still), "none").rmse > 0.1
    with pytest.raises(ValueError):
        evaluate_ate(gt, gt, "sim2")
