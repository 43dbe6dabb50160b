"""Timestamp association of a ground-truth and an estimated trajectory.

The rule is the nearest-timestamp association that evo uses, so that our
numbers and evo's agree pose for pose:

* The trajectory with **fewer** poses drives the matching (the estimate when
  both have the same length).  Each of its poses is paired with the pose of
  the other trajectory whose timestamp is closest, provided that
  ``|t_short - t_long| <= max_diff``; otherwise it is dropped.  Every pose of
  the shorter trajectory is therefore used at most once.  (A pose of the
  longer one can in principle be the nearest neighbour of two poses of the
  shorter one; with ``max_diff`` below half the sampling interval that
  cannot happen.)
* ``offset`` is added to the *estimated* timestamps before matching
  (``t_est + offset ≈ t_gt``).
* With sorted timestamps, the candidate is found by binary search; of the two
  neighbours ``t_lo ≤ t < t_hi`` the upper one wins only when it is strictly
  closer (ties go to the earlier pose).  Stamps further than ``max_diff``
  outside the other trajectory's time range are skipped.  Unsorted stamps
  fall back to a brute-force nearest neighbour (first minimum wins).

KITTI files have no timestamps; they are paired by index
(:func:`associate_by_index`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.errors import InputError
from droidw_cli.io.trajectory import Trajectory

_BRUTE_FORCE_BLOCK = 1 << 22  # elements of the |Δt| matrix held at once


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
    """Indices ``(i_short, i_long)`` of the nearest-timestamp matches within ``max_diff``.

    ``offset_long`` is added to ``stamps_long`` first.  Vectorised: a binary
    search over all short stamps at once.
    """
    short = np.asarray(stamps_short, dtype=np.float64)
    long_ = np.asarray(stamps_long, dtype=np.float64) + offset_long
    if short.size == 0 or long_.size == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    if not np.all(np.diff(long_) >= 0):
        return _brute_force_matches(short, long_, max_diff)

    inside = ~((short < long_[0] - max_diff) | (short > long_[-1] + max_diff))
    hi = np.minimum(np.searchsorted(long_, short, side="right"), long_.size - 1)
    diff_hi = long_[hi] - short
    diff_lo = np.where(hi > 0, short - long_[np.maximum(hi - 1, 0)], np.inf)
    take_hi = (diff_hi <= max_diff) & (diff_hi < diff_lo)
    take_lo = ~take_hi & (diff_lo <= max_diff) & (diff_lo <= diff_hi)
    keep = inside & (take_hi | take_lo)
    best = np.where(take_hi, hi, hi - 1)
    i_short = np.flatnonzero(keep)
    return i_short.astype(np.int64), best[keep].astype(np.int64)


def _brute_force_matches(short: np.ndarray, long_: np.ndarray, max_diff: float) -> tuple[np.ndarray, np.ndarray]:
    """Nearest neighbour by exhaustive |Δt|, in row blocks to bound memory."""
    rows = max(1, _BRUTE_FORCE_BLOCK // long_.size)
    best = np.empty(short.size, dtype=np.int64)
    best_diff = np.empty(short.size)
    for start in range(0, short.size, rows):  # blocks of stamps, not single stamps
        diffs = np.abs(long_[None, :] - short[start:start + rows, None])
        idx = np.argmin(diffs, axis=1)
        best[start:start + rows] = idx
        best_diff[start:start + rows] = diffs[np.arange(idx.size), idx]
    keep = best_diff <= max_diff
    return np.flatnonzero(keep).astype(np.int64), best[keep]


def associate(gt: Trajectory, est: Trajectory, max_diff: float = 0.02, offset: float = 0.0) -> Association:
    """Pair ground-truth and estimated poses by nearest timestamp (see module docstring).

    Raises :class:`AssociationError` when no pair is found.
    """
    if not (max_diff >= 0 and np.isfinite(max_diff)):
        raise ValueError(f"max_diff must be a finite non-negative number, got {max_diff}")
    est_longer = len(est) > len(gt)
    if est_longer:
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
