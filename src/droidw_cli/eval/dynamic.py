"""Evaluating dynamic/static separation against ground-truth masks.

* :func:`auroc`: the area under the ROC curve of a score (higher = more
  dynamic) against binary labels, by the rank-sum (Mann-Whitney U) identity
  AUROC = (R₊ − n₊(n₊ + 1)/2) / (n₊ n₋), ties given their mean rank.
* :func:`masks_on_grid`: ground-truth masks brought to the BA grid of a run
  (the same resize-and-crop as the frames, then 8×8 area averaging).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from droidw_cli.geometry.camera import BA_SCALE
from droidw_cli.io.prepare import FramePreparer


def auroc(scores: np.ndarray, labels: np.ndarray) -> float:
    """AUROC of ``scores`` for boolean ``labels`` (NaN if one class is missing)."""
    s = np.asarray(scores, dtype=np.float64).ravel()
    y = np.asarray(labels, dtype=bool).ravel()
    pos, neg = int(y.sum()), int((~y).sum())
    if pos == 0 or neg == 0:
        return float("nan")
    order = np.argsort(s, kind="mergesort")
    ranks = np.empty(len(s))
    sorted_s = s[order]
    # mean rank for ties
    _, first, counts = np.unique(sorted_s, return_index=True, return_counts=True)
    mean_rank = first + (counts - 1) / 2.0 + 1.0
    ranks[order] = np.repeat(mean_rank, counts)
    return float((ranks[y].sum() - pos * (pos + 1) / 2.0) / (pos * neg))


def masks_on_grid(mask_paths: list[Path], src_hw: tuple[int, int], target_area: int, frac: float = 0.5) -> np.ndarray:
    """(K, h, w) bool: each mask prepared like the frames, True where ≥ ``frac`` of the 8×8 block is dynamic."""
    prep = FramePreparer(src_hw, None, target_area)
    h, w = prep.size[0] // BA_SCALE, prep.size[1] // BA_SCALE
    out = np.zeros((len(mask_paths), h, w), dtype=bool)
    for k, p in enumerate(mask_paths):
        m = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if m is None:
            raise FileNotFoundError(p)
        work = prep.image(np.repeat(m[..., None], 3, axis=2))[..., 0].astype(np.float32) / 255.0
        out[k] = cv2.resize(work, (w, h), interpolation=cv2.INTER_AREA) >= frac
    return out
