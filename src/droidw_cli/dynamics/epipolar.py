"""Epipolar motion segmentation: movers are what the dominant rigid motion cannot explain.

droidw masks every window edge with this (slam/frontend.py), from the first
keyframes on.  There the learned uncertainty cannot separate movers yet: its
evidence is the multi-view geometry, and that
is exactly what movers covering a third of the view corrupt before any map
exists (DROID-W leans on a metric mono-depth prior there, which droidw cannot
obtain).  Two views of a rigid scene obey the epipolar constraint
x_jᵀ F x_i = 0 whatever the depths, so a fundamental matrix fitted robustly
to the dense flow describes the background as long as it covers more than
half of the confident pixels, and pixels far from their epipolar line move.

Per edge (i, j), on the block centres of the 1/8 grid (x_i, x_j = x_i + flow):

* F by RANSAC (OpenCV's 7-point RANSAC, whose generator starts from the same
  state on every call: deterministic; inliers within ``RANSAC_PX`` working px
  of their epipolar line, scaled with the image diagonal above 640 px: DIS's
  noise in working px does not shrink with the image, and at 120 × 160 a band
  scaled down to 0.09 px left a fifth of the movers unmasked), then ``REFITS`` times
  the normalised 8-point fit to the pixels whose Sampson distance is within
  2.5 σ, σ = 1.4826 · median (least median of squares' inlier rule), on the
  pixels whose correspondence confidence is at least ``min_weight`` (every n-th
  of them, at most ``FIT_POINTS`` and ``FIT_SHARE`` of the grid).  Least median
  of squares alone, as before 2026-11-28, took 8-18 ms an edge on 768 points,
  a tenth of a tracking run's CPU time (walk seed 1: about 10 s of 105), against
  about 1.2 ms for these fits, which find the movers about as well (fewer on follow seed 2; docs/benchmarks.md,
  "The epipolar fit by RANSAC and refits"; RANSAC alone at 1 px flagged 8-33 %
  fewer of the mover cells);
* the Sampson distance of every block centre, in working-resolution pixels:

      d² = (x_jᵀ F x_i)² / ((F x_i)₁² + (F x_i)₂² + (Fᵀ x_j)₁² + (Fᵀ x_j)₂²)

Per keyframe i, over its edges: moving where max_j d_j / τ_j > 1, with
τ_j = max(``thresh``, NOISE_FACTOR · median d_j) so that noisier flow (real
footage) raises the bar, then dilated by ``dilate`` grid cells (block
averages at a mover's outline are mixed, and a ring of background lost there
costs nothing: an oracle mask grown by 2 cells tracks as well as the exact
one), or by fewer when the grown mask would cover more than ``MAX_MOVING`` of
the view.  Walkers that cover a quarter to a third of it, close to a fast
turning camera, grow by 2 cells to 70-90 %; dropping such a mask, as every
mask over ``MAX_MOVING`` was before, left them in BA (rotate with walkers kept
apart, seed 1: 2.07 cm; grown by fewer cells: 0.93; ground-truth masks: 0.65).
The max, because a mover that walks along one epipolar line crosses
the lines of the other edges.  Recall matters more than precision: on the
synthetic movers, leaving 4-16 % of the confidence mass on movers still
derailed the map (ATE 20-30 cm), while zeroing half the background with
them gave 1 cm.
"""

from __future__ import annotations

import cv2
import numpy as np

from droidw_cli.geometry.camera import BA_SCALE

#: fewest confident block centres needed to fit F
MIN_POINTS = 16
#: F is fitted on at most about this many of them (every n-th; 23 ms for 3072 at 384×512, 7 ms for 768) ...
FIT_POINTS = 768
#: ... and at most this share of the grid's block centres: 384 at ``fast``'s 256×384 (32 × 48 grid)
FIT_SHARE = 0.25
#: the threshold of an edge is at least this many times its median Sampson distance
NOISE_FACTOR = 5.0
#: a keyframe whose mask would cover more than this share of the view is not masked
MAX_MOVING = 0.75
#: an edge is degenerate (near-pure rotation) when a homography explains its confident flow to a median
#: transfer error of at most DEGENERATE_PX working px (at the 384 × 512 default working size, 640 px diagonal;
#: scaled with the diagonal) and at most DEGENERATE_RATIO × F's median Sampson distance
DEGENERATE_PX = 1.0
DEGENERATE_RATIO = 4.0
#: RANSAC's inlier distance to the epipolar line (working px up to a 640 px image diagonal, scaled with larger ones)
RANSAC_PX = 0.3
#: 8-point refits of F to its robust inliers after RANSAC
REFITS = 2


def sampson_distance(fundamental: np.ndarray, x_i: np.ndarray, x_j: np.ndarray) -> np.ndarray:
    """(P,) Sampson distance of the correspondences x_i → x_j (P, 2) under F (3, 3)."""
    a = np.concatenate([x_i, np.ones((len(x_i), 1))], 1)
    b = np.concatenate([x_j, np.ones((len(x_j), 1))], 1)
    fa, ftb = a @ fundamental.T, b @ fundamental
    num = np.sum(b * fa, axis=1) ** 2
    den = fa[:, 0] ** 2 + fa[:, 1] ** 2 + ftb[:, 0] ** 2 + ftb[:, 1] ** 2
    return np.sqrt(num / np.maximum(den, 1e-12))


def fit_fundamental(x_i: np.ndarray, x_j: np.ndarray, inlier_px: float) -> np.ndarray | None:
    """F (3, 3) of the correspondences x_i → x_j (P, 2) by RANSAC and ``REFITS`` 8-point refits (module
    docstring); None where OpenCV finds none."""
    fundamental, _ = cv2.findFundamentalMat(x_i, x_j, cv2.FM_RANSAC, inlier_px, 0.999)
    if fundamental is None or fundamental.shape != (3, 3):
        return None
    for _ in range(REFITS):
        d = sampson_distance(fundamental, x_i, x_j)
        keep = d <= max(2.5 * 1.4826 * float(np.median(d)), 1e-6)
        if keep.sum() < MIN_POINTS:
            break
        refit, _ = cv2.findFundamentalMat(x_i[keep], x_j[keep], cv2.FM_8POINT)
        if refit is None or refit.shape != (3, 3):
            break
        fundamental = refit
    return fundamental


def block_centres(height: int, width: int) -> np.ndarray:
    """(h·w, 2) float64 (x, y) working-resolution centres of the 1/8 grid blocks, row-major."""
    half = (BA_SCALE - 1) / 2.0
    xs = np.arange(width // BA_SCALE) * BA_SCALE + half
    ys = np.arange(height // BA_SCALE) * BA_SCALE + half
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], 1)


def epipolar_distance(flow: np.ndarray, weight: np.ndarray, min_weight: float = 0.2) -> np.ndarray | None:
    """(h, w) Sampson distance (px) of each grid block's flow to the dominant epipolar geometry.

    flow (H, W, 2) full-resolution flow i → j; weight (h, w) confidence on the
    1/8 grid.  None when too few confident pixels or F cannot be fitted.
    """
    height, width = flow.shape[:2]
    h, w = height // BA_SCALE, width // BA_SCALE
    x_i = block_centres(height, width)
    # bilinear flow at the block centre = mean of the 2×2 central pixels of each block
    c = BA_SCALE // 2
    core = flow[: h * BA_SCALE, : w * BA_SCALE].reshape(h, BA_SCALE, w, BA_SCALE, 2)[:, c - 1:c + 1, :, c - 1:c + 1]
    x_j = x_i + core.mean(axis=(1, 3)).reshape(-1, 2).astype(np.float64)
    sel = np.asarray(weight).reshape(-1) >= min_weight
    if sel.sum() < MIN_POINTS:
        return None
    idx = np.flatnonzero(sel)
    fit_points = max(MIN_POINTS, min(FIT_POINTS, int(FIT_SHARE * h * w)))
    idx = idx[:: -(-len(idx) // fit_points)]  # a regular subsample: the fits' time grows with the points
    scale = float(np.hypot(height, width)) / 640.0
    fundamental = fit_fundamental(x_i[idx], x_j[idx], RANSAC_PX * max(scale, 1.0))
    if fundamental is None:
        return None
    sampson = sampson_distance(fundamental, x_i, x_j)
    homography, _ = cv2.findHomography(x_i[idx], x_j[idx], cv2.LMEDS)
    if homography is not None and homography.shape == (3, 3):
        # near-pure rotation: x_j = H x_i fits the background, and F = [e']× H for any epipole e', so the
        # fitted epipolar lines are arbitrary and a mover walking along them is missed: test against H
        transfer = np.linalg.norm(cv2.perspectiveTransform(x_i[None], homography)[0] - x_j, axis=1)
        med = float(np.median(transfer[idx]))
        limit = min(DEGENERATE_PX * scale,
                    DEGENERATE_RATIO * float(np.median(sampson[idx])))
        if med <= limit:
            return transfer.reshape(h, w).astype(np.float32)
    return sampson.reshape(h, w).astype(np.float32)


def moving_mask(distances: list[np.ndarray], thresh: float, dilate: int, limit: float = 1.0,
                seen: list[np.ndarray] | None = None) -> np.ndarray:
    """(h, w) bool: some edge's Sampson distance above its threshold, dilated by ``dilate`` cells, or by
    fewer when the grown mask would cover more than ``limit`` of the view (the largest growth within it;
    the undilated mask when none is).

    ``seen`` (one (h, w) bool map an edge, optional): the cells the edge measured, those that the map or the
    measured flow keeps inside its other frame (:meth:`~droidw_cli.slam.keyframe_maps.KeyframeMaps.in_view`).
    A cell outside it was not measured on that edge: DIS's flow there is extrapolated, its distance is no
    evidence of motion, and it neither counts on that edge nor enters the edge's median."""
    mask = np.zeros(distances[0].shape, dtype=bool)
    for n, d in enumerate(distances):
        keep = np.ones(d.shape, dtype=bool) if seen is None else np.asarray(seen[n], dtype=bool)
        if not keep.any():
            continue
        mask |= keep & (d > max(thresh, NOISE_FACTOR * float(np.median(d[keep]))))
    for grow in range(dilate, 0, -1):
        if not mask.any():
            break
        kernel = np.ones((2 * grow + 1, 2 * grow + 1), np.uint8)
        grown = cv2.dilate(mask.astype(np.uint8), kernel) > 0
        if grown.mean() <= limit:
            return grown
    return mask
