"""Absolute and relative trajectory error.

ATE (translation part, as evo's APE): after associating and aligning,

    e_i = || p_gt,i - (c R p_est,i + t) ||,   RMSE = sqrt(mean e_i²)

with mean, median, max, min and (population) std of ``e_i``.

RPE (translation part, as evo's RPE with ``delta`` in frames, consecutive
pairs): for the matched, aligned poses take index pairs
``(0, Δ), (Δ, 2Δ), …`` and

    E_k = (Q_i⁻¹ Q_j)⁻¹ (P_i⁻¹ P_j),   e_k = || trans(E_k) ||

where ``Q`` are ground-truth and ``P`` aligned estimated camera-to-world
poses.  With Sim(3) alignment the estimate's translations carry the scale,
so RPE is in metres of the ground truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.eval.align import Sim3, align_positions
from droidw_cli.eval.associate import Association, AssociationError, associate, associate_by_index
from droidw_cli.io.trajectory import Trajectory

MIN_MATCHES = 3


@dataclass(frozen=True)
class ErrorStats:
    """Summary statistics of a vector of non-negative errors (metres)."""

    rmse: float
    mean: float
    median: float
    max: float
    min: float
    std: float
    count: int

    @staticmethod
    def from_errors(errors: np.ndarray) -> "ErrorStats":
        e = np.asarray(errors, dtype=np.float64)
        if e.size == 0:
            raise ValueError("no errors to summarise")
        return ErrorStats(
            rmse=float(np.sqrt(np.mean(e * e))), mean=float(np.mean(e)), median=float(np.median(e)),
            max=float(np.max(e)), min=float(np.min(e)), std=float(np.std(e)), count=int(e.size),
        )

    def as_dict(self) -> dict[str, float | int]:
        return {"rmse": self.rmse, "mean": self.mean, "median": self.median, "max": self.max,
                "min": self.min, "std": self.std, "count": self.count}


@dataclass(frozen=True, eq=False)
class AteResult:
    """ATE of an estimated trajectory against ground truth after association and alignment.

    ``positions`` are the aligned estimated positions of the matched poses
    (M, 3); ``gt_positions`` the matching ground-truth ones; ``errors`` the
    per-pose distances; ``gt_index`` / ``est_index`` the matched pose indices.
    """

    rmse: float
    mean: float
    median: float
    max: float
    std: float
    matches: int
    scale: float
    rotation: np.ndarray
    translation: np.ndarray
    positions: np.ndarray
    gt_positions: np.ndarray
    errors: np.ndarray
    gt_index: np.ndarray
    est_index: np.ndarray
    align: str = "sim3"

    @property
    def min(self) -> float:
        return float(np.min(self.errors))

    @property
    def transform(self) -> Sim3:
        return Sim3(self.rotation, self.translation, self.scale)

    @property
    def stats(self) -> ErrorStats:
        return ErrorStats.from_errors(self.errors)


@dataclass(frozen=True)
class RpeResult:
    """Translational RPE over pose pairs ``delta`` matched frames apart."""

    delta: int
    stats: ErrorStats


class TooFewMatchesError(InputError):
    """Fewer matched poses than an alignment needs."""


def match(gt: Trajectory, est: Trajectory, max_diff: float = 0.02, offset: float = 0.0,
          by_index: bool = False) -> Association:
    """Associate ``gt`` and ``est`` and insist on at least :data:`MIN_MATCHES` pairs."""
    assoc = associate_by_index(gt, est) if by_index else associate(gt, est, max_diff, offset)
    if len(assoc) < MIN_MATCHES:
        how = "by index" if by_index else f"within {max_diff:g} s"
        raise TooFewMatchesError(
            f"only {len(assoc)} pose(s) of the estimate match the ground truth {how}; at least {MIN_MATCHES} needed"
        )
    return assoc


def evaluate_ate(gt: Trajectory, est: Trajectory, align: str = "sim3", max_diff: float = 0.02, *,
                 offset: float = 0.0, by_index: bool = False) -> AteResult:
    """Associate, align (``sim3`` | ``se3`` | ``none``) and compute the ATE of ``est`` against ``gt``.

    Raises :class:`AssociationError` (no common timestamps),
    :class:`TooFewMatchesError` (< 3 pairs) or
    :class:`~droidw_cli.eval.align.DegenerateGeometryError`, all ``InputError``.
    """
    assoc = match(gt, est, max_diff, offset, by_index)
    gt_pos = gt.positions[assoc.gt_index]
    est_pos = est.positions[assoc.est_index]
    sim3 = align_positions(est_pos, gt_pos, align)
    aligned = sim3.apply_points(est_pos)
    errors = np.linalg.norm(gt_pos - aligned, axis=1)
    s = ErrorStats.from_errors(errors)
    return AteResult(
        rmse=s.rmse, mean=s.mean, median=s.median, max=s.max, std=s.std, matches=s.count,
        scale=float(sim3.scale), rotation=sim3.rotation, translation=sim3.translation,
        positions=aligned, gt_positions=gt_pos, errors=errors,
        gt_index=assoc.gt_index, est_index=assoc.est_index, align=align,
    )


def relative_errors(gt_poses: np.ndarray, est_poses: np.ndarray, delta: int) -> np.ndarray:
    """Translational RPE of consecutive pairs ``(kΔ, (k+1)Δ)`` of two matched (N, 4, 4) pose stacks."""
    if delta < 1:
        raise ValueError(f"delta must be a positive number of frames, got {delta}")
    if gt_poses.shape != est_poses.shape:
        raise ValueError("pose stacks differ in shape")
    ids = np.arange(0, gt_poses.shape[0], delta)
    i, j = ids[:-1], ids[1:]
    q_rel = _se3_inverse(gt_poses[i]) @ gt_poses[j]
    p_rel = _se3_inverse(est_poses[i]) @ est_poses[j]
    e = _se3_inverse(q_rel) @ p_rel
    return np.linalg.norm(e[:, :3, 3], axis=1)


def _se3_inverse(poses: np.ndarray) -> np.ndarray:
    """(N, 4, 4) rigid transforms → inverses ``[Rᵀ | -Rᵀ t]``."""
    inv = np.zeros_like(poses)
    rt = np.swapaxes(poses[:, :3, :3], 1, 2)
    inv[:, :3, :3] = rt
    inv[:, :3, 3] = -(rt @ poses[:, :3, 3:4])[:, :, 0]
    inv[:, 3, 3] = 1.0
    return inv


def evaluate_rpe(gt: Trajectory, est: Trajectory, ate: AteResult, delta: int = 1) -> RpeResult:
    """RPE of the matched poses of an :func:`evaluate_ate` result, after its alignment."""
    gt_poses = gt.poses[ate.gt_index]
    est_poses = ate.transform.apply_poses(est.poses[ate.est_index])
    errors = relative_errors(gt_poses, est_poses, int(delta))
    if errors.size == 0:
        raise TooFewMatchesError(
            f"RPE delta {delta} is too large for {ate.matches} matched poses (needs at least {delta + 1})"
        )
    return RpeResult(int(delta), ErrorStats.from_errors(errors))


__all__ = [
    "AteResult", "AssociationError", "ErrorStats", "RpeResult", "TooFewMatchesError",
    "evaluate_ate", "evaluate_rpe", "match", "relative_errors",
]
