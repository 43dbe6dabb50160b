"""Pixel-level helpers of the object tracker (:mod:`droidw_cli.dynamics.tracker`).

* :func:`shift_mask` moves a mask by whole pixels (the prediction of an object's mask);
* :func:`depth_components` splits a dynamic mask into connected components that do
  not cross a depth step (two walkers at different depths touching in the image);
* :func:`colour_bins` / :func:`colour_histogram` / :func:`bhattacharyya`: the
  appearance model, a COLOUR_BINS³ RGB histogram with add-one smoothing;
* :func:`median_depth`, :func:`distance_to`.
"""

from __future__ import annotations

import cv2
import numpy as np

from droidw_cli.dynamics.refine import label_components

#: colour histograms of the objects: this many bins per RGB channel
COLOUR_BINS = 4

_NEIGHBOURS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def shift_mask(mask: np.ndarray, dx: int, dy: int) -> np.ndarray:
    """``mask`` (h, w) bool moved by (dx, dy) pixels; what leaves the image is dropped."""
    h, w = mask.shape
    out = np.zeros_like(mask)
    if abs(dx) >= w or abs(dy) >= h:
        return out
    out[max(0, dy):h + min(0, dy), max(0, dx):w + min(0, dx)] = mask[max(0, -dy):h - max(0, dy),
                                                                      max(0, -dx):w - max(0, dx)]
    return out


def _neighbour(a: np.ndarray, dy: int, dx: int, fill) -> np.ndarray:
    """a[y + dy, x + dx] at every pixel (``fill`` outside the image)."""
    h, w = a.shape
    p = np.pad(a, 1, constant_values=fill)
    return p[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]


def depth_components(mask: np.ndarray, depth: np.ndarray | None, step: float) -> np.ndarray:
    """8-connected components of ``mask`` that do not cross a depth step; labels (h, w) int64, 0 background.

    A pixel is on the far side of a step when an 8-neighbour in the mask is nearer by more than
    ``step`` in log depth (both depths known).  The components of the mask without those pixels
    are labelled; each far pixel then joins the neighbouring label whose depth is closest (within
    ``step``), three rounds; far pixels left over form components of their own.  Without depth
    (or ``step`` ≤ 0) these are the plain 8-connected components.
    """
    if depth is None or step <= 0:
        return label_components(mask).numpy()
    logd = np.where(depth > 0, np.log(np.maximum(depth, 1e-9)), np.nan)
    far = np.zeros_like(mask)
    with np.errstate(invalid="ignore"):
        for dy, dx in _NEIGHBOURS:
            far |= mask & _neighbour(mask, dy, dx, False) & (logd - _neighbour(logd, dy, dx, np.nan) > step)
    labels = label_components(mask & ~far).numpy()
    for _ in range(3):
        todo = far & (labels == 0)
        if not todo.any():
            break
        best, gap = np.zeros_like(labels), np.full(mask.shape, np.inf)
        for dy, dx in _NEIGHBOURS:
            lab = _neighbour(labels, dy, dx, 0)
            with np.errstate(invalid="ignore"):
                diff = np.abs(logd - _neighbour(logd, dy, dx, np.nan))
            better = todo & (lab > 0) & (diff <= step) & (diff < gap)
            best, gap = np.where(better, lab, best), np.where(better, diff, gap)
        labels = np.where(best > 0, best, labels)
    rest = label_components(far & (labels == 0)).numpy()
    return np.where(rest > 0, rest + labels.max(), labels)


def colour_bins(image: np.ndarray) -> np.ndarray:
    """(h, w) int: the colour-histogram bin of each pixel of an (h, w, 3) image in [0, 1]."""
    q = np.clip((np.asarray(image, dtype=np.float64) * COLOUR_BINS).astype(np.int64), 0, COLOUR_BINS - 1)
    return (q[..., 0] * COLOUR_BINS + q[..., 1]) * COLOUR_BINS + q[..., 2]


def colour_histogram(bins: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Normalised histogram (COLOUR_BINS³,) of the bins under ``mask``, each bin counted once more (add-one)."""
    hist = np.bincount(bins[mask], minlength=COLOUR_BINS ** 3) + 1.0
    return hist / hist.sum()


def bhattacharyya(p: np.ndarray, q: np.ndarray) -> float:
    """Bhattacharyya coefficient Σ √(p q) of two normalised histograms (1: identical)."""
    return float(np.sqrt(p * q).sum())


def median_depth(mask: np.ndarray, depth: np.ndarray | None) -> float:
    """Median of ``depth`` over the pixels of ``mask`` where it is known (> 0); 0 if none."""
    if depth is None:
        return 0.0
    d = depth[mask & (depth > 0)]
    return float(np.median(d)) if d.size else 0.0


def distance_to(mask: np.ndarray) -> np.ndarray:
    """Euclidean distance of every pixel to the nearest pixel of ``mask`` (0 inside)."""
    return cv2.distanceTransform((~mask).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
