"""Timestamp association of a ground-truth and an estimated trajectory, by evo.

The matching is :func:`evo.core.sync.matching_time_indices` with the rule of
:func:`evo.core.sync.associate_trajectories`: the trajectory with **fewer**
poses drives (the estimate when both have the same length), each of its poses
is paired with the nearest-timestamp pose of the other within ``max_diff``
(ties go to the earlier pose), and ``offset`` is added to the estimated
timestamps (``t_est + offset ≈ t_gt``).  droidw keeps the matched indices,
which evo's trajectory-level call does not return, and its own error when
nothing matches.

KITTI files have no timestamps; they are paired by index
(:func:`associate_by_index`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.io.trajectory import Trajectory


class AssociationError(InputError):
    """The two trajectories cannot be paired (no common time span)."""


@dataclass(frozen=True, eq=False)
class Association:
    """Index pairs ``(gt_index[k], est_index[k])``, in the order of the driving trajectory."""

    gt_index: np.ndarray
    est_index: np.ndarray

    def __len__(self) -> int:
        return int(self.gt_index.shape[0])


def nearest_matches(
    stamps_short: np.ndarray, stamps_long: np.ndarray, max_diff: float, offset_long: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Indices ``(i_short, i_long)`` of evo's nearest-timestamp matches within ``max_diff``.

    ``offset_long`` is added to ``stamps_long`` first.
    """
    from evo.core.sync import matching_time_indices

    short = np.asarray(stamps_short, dtype=np.float64)
    long_ = np.asarray(stamps_long, dtype=np.float64)
    if short.size == 0 or long_.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    i_short, i_long = matching_time_indices(short, long_.copy(), max_diff=max_diff, offset_2=offset_long)
    return np.asarray(i_short, dtype=np.int64), np.asarray(i_long, dtype=np.int64)


def associate(gt: Trajectory, est: Trajectory, max_diff: float = 0.02, offset: float = 0.0) -> Association:
    """Pair ground-truth and estimated poses by nearest timestamp (see module docstring).

    Raises :class:`AssociationError` when no pair is found.
    """
    if not (max_diff >= 0 and np.isfinite(max_diff)):
        raise ValueError(f"max_diff must be a finite non-negative number, got {max_diff}")
    if len(est) > len(gt):  # as evo.core.sync.associate_trajectories(gt, est): the shorter one drives
        i_gt, i_est = nearest_matches(gt.timestamps, est.timestamps, max_diff, offset)
    else:
        i_est, i_gt = nearest_matches(est.timestamps, gt.timestamps, max_diff, -offset)
    if i_gt.size == 0:
        raise AssociationError(
            f"no overlapping timestamps: no estimated pose is within {max_diff:g} s of a ground-truth pose "
            f"(ground truth spans {_span(gt.timestamps)}, estimate {_span(est.timestamps + offset)})"
        )
    return Association(i_gt, i_est)


def associate_by_index(gt: Trajectory, est: Trajectory) -> Association:
    """Pair pose ``i`` with pose ``i`` (trajectories without timestamps, e.g. KITTI)."""
    if len(gt) != len(est):
        raise AssociationError(
            f"trajectories without timestamps are paired by index, but the ground truth has {len(gt)} "
            f"poses and the estimate {len(est)}; give a times file for each"
        )
    idx = np.arange(len(gt), dtype=np.int64)
    return Association(idx, idx.copy())


def _span(t: np.ndarray) -> str:
    if t.size == 0:
        return "nothing"
    return f"{float(np.min(t)):.6f}..{float(np.max(t)):.6f} s"
