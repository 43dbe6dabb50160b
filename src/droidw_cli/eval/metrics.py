"""Absolute and relative trajectory error, computed by evo.

ATE is evo's APE of the translation part (``evo_ape ... -a [-s]``) on the
associated poses after Umeyama alignment, ``e_i = ‖p_gt,i − (c R p_est,i + t)‖``:
:func:`evaluate_ate` builds the two ``PoseTrajectory3D`` and calls
:func:`evo.main_ape.ape`, whose :class:`evo.core.result.Result` it keeps (so
that ``--save-results`` writes exactly what ``evo_ape --save_results`` would).

RPE is evo's ``metrics.RPE`` (translation part, ``delta`` in frames,
consecutive pairs ``(0, Δ), (Δ, 2Δ), …``) on the matched poses after the same
alignment, so with Sim(3) it is in metres of the ground truth.

droidw adds its own checks and messages in front: no common timestamps,
fewer than :data:`MIN_MATCHES` pairs, identical or collinear positions.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.eval.align import ALIGN_MODES, Sim3, check_alignable
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

    @staticmethod
    def from_evo(stats: dict, count: int) -> "ErrorStats":
        """From evo's ``get_all_statistics()`` dict."""
        return ErrorStats(**{k: float(stats[k]) for k in ("rmse", "mean", "median", "max", "min", "std")},
                          count=int(count))

    def as_dict(self) -> dict[str, float | int]:
        return {"rmse": self.rmse, "mean": self.mean, "median": self.median, "max": self.max,
                "min": self.min, "std": self.std, "count": self.count}


@dataclass(frozen=True, eq=False)
class AteResult:
    """ATE of an estimated trajectory against ground truth after association and alignment.

    ``positions`` are the aligned estimated positions of the matched poses
    (M, 3); ``gt_positions`` the matching ground-truth ones; ``errors`` the
    per-pose distances; ``gt_index`` / ``est_index`` the matched pose indices;
    ``evo_result`` evo's APE result object (info, stats, error array, aligned
    trajectories).
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
    min: float = 0.0
    evo_result: Any = field(default=None, repr=False)

    @property
    def transform(self) -> Sim3:
        return Sim3(self.rotation, self.translation, self.scale)

    @property
    def stats(self) -> ErrorStats:
        return ErrorStats(self.rmse, self.mean, self.median, self.max, self.min, self.std, self.matches)


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


def evo_trajectory(traj: Trajectory, index: np.ndarray | None = None, name: str | None = None):
    """An ``evo.core.trajectory.PoseTrajectory3D`` of ``traj`` (or of its poses ``index``)."""
    from evo.core.trajectory import PoseTrajectory3D

    t = traj if index is None else traj.subset(index)
    out = PoseTrajectory3D(poses_se3=list(np.asarray(t.poses, dtype=np.float64)),
                           timestamps=np.asarray(t.timestamps, dtype=np.float64).copy())
    out.name = name  # evo ≥ 1.3x labels results by it (older ones take names as ape() arguments)
    return out


def evaluate_ate(gt: Trajectory, est: Trajectory, align: str = "sim3", max_diff: float = 0.02, *,
                 offset: float = 0.0, by_index: bool = False,
                 names: tuple[str, str] = ("reference", "estimate")) -> AteResult:
    """Associate, align (``sim3`` | ``se3`` | ``none``) and compute the ATE of ``est`` against ``gt`` with evo.

    ``names`` label the ground truth and the estimate in evo's result.
    Raises :class:`AssociationError` (no common timestamps),
    :class:`TooFewMatchesError` (< 3 pairs) or
    :class:`~droidw_cli.eval.align.DegenerateGeometryError`, all ``InputError``.
    """
    if align not in ALIGN_MODES:
        raise ValueError(f"unknown alignment {align!r}; use one of {', '.join(ALIGN_MODES)}")
    from evo.core import metrics
    from evo.main_ape import ape

    assoc = match(gt, est, max_diff, offset, by_index)
    gt_pos = gt.positions[assoc.gt_index]
    if align != "none":
        check_alignable(est.positions[assoc.est_index], gt_pos)
    ref_name, est_name = names
    extra = {"ref_name": ref_name, "est_name": est_name} if "est_name" in inspect.signature(ape).parameters else {}
    result = ape(evo_trajectory(gt, assoc.gt_index, ref_name), evo_trajectory(est, assoc.est_index, est_name),
                 metrics.PoseRelation.translation_part, align=align != "none", correct_scale=align == "sim3",
                 **extra)
    sim3 = (Sim3.from_matrix(result.np_arrays["alignment_transformation_sim3"]) if align != "none"
            else Sim3.identity())
    if align != "sim3":
        sim3 = Sim3(sim3.rotation, sim3.translation, 1.0)
    errors = np.asarray(result.np_arrays["error_array"], dtype=np.float64)
    s = ErrorStats.from_evo(result.stats, errors.size)
    return AteResult(
        rmse=s.rmse, mean=s.mean, median=s.median, max=s.max, std=s.std, min=s.min, matches=s.count,
        scale=float(sim3.scale), rotation=sim3.rotation, translation=sim3.translation,
        positions=np.asarray(result.trajectories[result.info["est_name"]].positions_xyz, dtype=np.float64),
        gt_positions=gt_pos,
        errors=errors, gt_index=assoc.gt_index, est_index=assoc.est_index, align=align, evo_result=result,
    )


def relative_errors(gt_poses: np.ndarray, est_poses: np.ndarray, delta: int) -> np.ndarray:
    """evo's translational RPE of consecutive pairs ``(kΔ, (k+1)Δ)`` of two matched (N, 4, 4) pose stacks."""
    from evo.core import metrics
    from evo.core.trajectory import PosePath3D

    if delta < 1:
        raise ValueError(f"delta must be a positive number of frames, got {delta}")
    if gt_poses.shape != est_poses.shape:
        raise ValueError("pose stacks differ in shape")
    if gt_poses.shape[0] <= delta:
        return np.zeros(0)
    rpe = metrics.RPE(metrics.PoseRelation.translation_part, int(delta), metrics.Unit.frames, all_pairs=False)
    rpe.process_data((PosePath3D(poses_se3=list(np.asarray(gt_poses, dtype=np.float64))),
                      PosePath3D(poses_se3=list(np.asarray(est_poses, dtype=np.float64)))))
    return np.asarray(rpe.error, dtype=np.float64)


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


def heading_error(gt_poses: np.ndarray, est_poses: np.ndarray) -> float:
    """The angle (degrees) between the true and estimated directions of travel from the first pose to the last.

    For camera-to-world poses (N, 4, 4) with centres c_k and first rotation R₀, each trajectory's
    direction of travel seen from its first camera is d = R₀ᵀ (c_{N−1} − c₀), and the error is
    ∠(d_gt, d_est).  It needs no alignment and ignores the scale, so over a monocular run's first
    keyframes it tells whether initialisation found the way the camera went (a forward motion taken
    for a sideways one plus a turn shows here first).
    """
    gt, est = np.asarray(gt_poses, np.float64), np.asarray(est_poses, np.float64)
    if gt.shape != est.shape or gt.ndim != 3 or gt.shape[0] < 2:
        raise ValueError(f"need two matching stacks of at least 2 poses, got {gt.shape} and {est.shape}")
    dirs = []
    for poses in (gt, est):
        d = poses[0, :3, :3].T @ (poses[-1, :3, 3] - poses[0, :3, 3])
        norm = float(np.linalg.norm(d))
        if norm == 0.0:
            raise ValueError("the camera does not move between the first and the last pose")
        dirs.append(d / norm)
    return float(np.degrees(np.arccos(np.clip(dirs[0] @ dirs[1], -1.0, 1.0))))


__all__ = [
    "AteResult", "AssociationError", "ErrorStats", "RpeResult", "TooFewMatchesError",
    "evaluate_ate", "evaluate_rpe", "evo_trajectory", "heading_error", "match", "relative_errors",
]

