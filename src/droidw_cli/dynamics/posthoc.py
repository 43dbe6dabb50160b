"""Monocular output masks: the flow that the final poses cannot explain whatever the depth.

Without a depth sensor the depth of a mover in BA is unconstrained (its
confidence was zeroed), so the scene-consistency test, which compares depths,
fails on it.  The geometry of the final relative poses still constrains the
flow of every static pixel whatever its depth.  For keyframe k and a kept
short edge k → j (``KeyframeMasks.edges``: the grid flow target p*_kj and its
confidence), with the final world-to-camera poses G_k, G_j, R, t of
G_j G_k⁻¹ and the grid intrinsics K, a static pixel x of inverse depth ρ ≥ 0
lands on

    q(ρ) = π(R K⁻¹ x̃ + ρ t),

a segment of its epipolar line from the point at infinity q(0) (pure
rotation: a single point) to q(ρ_max).  The *motion distance* of x on the
edge is the distance of p*_kj to that segment, in grid px: zero for any static
pixel, whatever BA made of its depth; at least the component of a mover's
motion across its epipolar line, or its motion past the segment's ends.
ρ_max = ``RHO_FACTOR`` × the 98th percentile of keyframe k's BA inverse depth
(the scene's nearest structure with a margin; the scale is BA's).  The segment
is sampled at ``SAMPLES`` inverse depths (the distance to the polyline).

Per edge e the threshold is τ_e = max(``min_px``, ``noise`` · median_e), the
median over the confident pixels (weight ≥ ``min_weight``), and the pixel's
score is distance / τ_e; pixels below ``min_weight`` score 0 on that edge.
The keyframe's score is the largest over its edges.

Most of a mover's cells have no confident flow on any edge (the
correspondence's forward-backward confidence fails on a body that deforms
and moves: on the walk preset 42 % of the cells with zero confidence on every
edge are movers, against 4 % of the confident ones), while on the static
background such cells are thin lines along occlusion edges, specks, and
blurred or textureless patches (on the fast-rotation preset as many
unconfident cells are static as are movers).  So, with S = (score > 1) and
L = (max_e weight_e < ``low_weight``),

    M_k = clean(support(open₃ₓ₃(S ∪ L), S))

where the opening removes the thin lines, ``support`` keeps the 8-connected
components with at least ``min_seed`` cells of S (unconfident flow is a mover
only where the geometry sees one moving: mask IoU rotate 0.69 → 0.71, walk
0.81 → 0.82, wobble 0.84, stopgo 0.83 → 0.85), and ``clean`` is a 3 × 3 closing,
components under ``min_area`` cells dropped and holes filled.  Keyframes
without a kept edge get an empty mask.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import Tensor

from droidw_cli.geometry.poses import invert, to_matrix

#: the segment of admissible static positions runs up to this many times keyframe k's 98th-percentile disparity
RHO_FACTOR = 3.0
#: inverse depths sampled along the segment
SAMPLES = 24


@dataclass(frozen=True)
class MotionParams:
    """Thresholds of the monocular motion masks (see the module docstring)."""

    min_px: float = 0.2
    noise: float = 4.0
    min_weight: float = 0.2
    low_weight: float = 0.2
    min_area: int = 4
    close: int = 1
    min_seed: int = 3  # cells of S a component needs (0 keeps every component)


def motion_distance(target: np.ndarray, rot: np.ndarray, trans: np.ndarray, kk: np.ndarray,
                    rho_max: float) -> np.ndarray:
    """(h, w) distance (grid px) of the flow targets (h, w, 2) to each pixel's static segment q([0, ρ_max])."""
    h, w = target.shape[:2]
    fx, fy, cx, cy = (float(v) for v in kk)
    gy, gx = np.meshgrid(np.arange(h, dtype=np.float64), np.arange(w, dtype=np.float64), indexing="ij")
    rays = np.stack([(gx - cx) / fx, (gy - cy) / fy, np.ones_like(gx)], -1) @ rot.T  # (h, w, 3)
    rho = np.linspace(0.0, rho_max, SAMPLES)
    pts = rays[None] + rho[:, None, None, None] * trans  # (S, h, w, 3)
    z = pts[..., 2]
    ok = z > 1e-6
    zs = np.where(ok, z, 1.0)
    q = np.stack([fx * pts[..., 0] / zs + cx, fy * pts[..., 1] / zs + cy], -1)  # (S, h, w, 2)
    y = target.astype(np.float64)[None]
    a, b = q[:-1], q[1:]
    ab = b - a
    t = np.clip(((y - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    d = np.linalg.norm(a + t[..., None] * ab - y, axis=-1)
    d = np.where(ok[:-1] & ok[1:], d, np.inf)
    d0 = np.where(ok[0], np.linalg.norm(q[0] - y[0], axis=-1), np.inf)
    out = np.minimum(d.min(0), d0)
    return np.where(np.isfinite(out), out, 0.0)


def edge_scores(k: int, edges: list[tuple[int, np.ndarray, np.ndarray]], c2w: np.ndarray, disp: np.ndarray,
                kk: np.ndarray, p: MotionParams) -> tuple[np.ndarray, np.ndarray]:
    """Keyframe k's (E, h, w) score distance / τ_e on each of its kept edges ``(j, target, weight)`` and
    (E, h, w) confidence in [0, 1]."""
    valid = disp[disp > 0]
    rho_max = RHO_FACTOR * float(np.percentile(valid, 98)) if valid.size else 1.0
    scores, weights = [], []
    for j, target, weight in edges:
        if j >= len(c2w):
            continue
        conf = weight.astype(np.float64) / 255.0
        weights.append(conf)
        ok = conf >= p.min_weight
        if ok.sum() < 16:
            continue
        rel = np.linalg.inv(c2w[j]) @ c2w[k]  # camera k → camera j
        dist = motion_distance(target, rel[:3, :3], rel[:3, 3], kk, rho_max)
        tau = max(p.min_px, p.noise * float(np.median(dist[ok])))
        scores.append(np.where(ok, dist / tau, 0.0))
    h, w = disp.shape
    empty = np.zeros((0, h, w))
    return (np.stack(scores) if scores else empty), (np.stack(weights) if weights else empty)


def keyframe_mask(scores: np.ndarray, weights: np.ndarray, p: MotionParams) -> np.ndarray:
    """(h, w) bool motion mask from a keyframe's per-edge scores and confidences (see the module docstring)."""
    if len(weights) == 0:
        return np.zeros(weights.shape[1:], bool)
    moving = scores.max(0) > 1.0 if len(scores) else np.zeros(weights.shape[1:], bool)
    seed = (weights.max(0) < p.low_weight) | moving
    seed = cv2.morphologyEx(seed.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    if p.min_seed > 0:
        n, lab = cv2.connectedComponents(seed, connectivity=8)
        support = np.bincount(lab[moving & (seed > 0)], minlength=n) >= p.min_seed
        support[0] = False
        return clean(support[lab], p)
    return clean(seed > 0, p)


def clean(seed: np.ndarray, p: MotionParams) -> np.ndarray:
    """Closing, small components dropped, holes filled (h, w) bool."""
    m = seed.astype(np.uint8)
    if p.close > 0:
        kernel = np.ones((2 * p.close + 1, 2 * p.close + 1), np.uint8)
        m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, kernel)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    keep = np.zeros(n, bool)
    keep[1:] = stats[1:, cv2.CC_STAT_AREA] >= p.min_area
    m = keep[lab]
    # holes: background components not touching the border
    inv = (~m).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(inv, connectivity=4)
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    hole = np.ones(n, bool)
    hole[border] = False
    hole[0] = False
    return m | (hole[lab] & (inv > 0))


def motion_masks(edges: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]], poses_w2c: Tensor, disps: Tensor,
                 intrinsics: Tensor, keyframes: range | None = None,
                 params: MotionParams | None = None) -> list[Tensor]:
    """(h, w) bool motion mask of each of ``keyframes`` (default: all of ``poses_w2c``) from its kept edges
    under the final poses."""
    p = params or MotionParams()
    ks = range(len(poses_w2c)) if keyframes is None else keyframes
    by_source: dict[int, list[tuple[int, np.ndarray, np.ndarray]]] = {k: [] for k in ks}
    for (i, j), (target, weight) in sorted(edges.items()):
        if i in by_source:
            by_source[i].append((j, target, weight))
    c2w = to_matrix(invert(poses_w2c.detach().double().cpu()))
    kk = intrinsics.detach().double().cpu().numpy()
    out = []
    for k in ks:
        d = disps[k].detach().float().cpu().numpy()
        scores, weights = edge_scores(k, by_source[k], c2w, d, kk, p)
        out.append(torch.from_numpy(keyframe_mask(scores, weights, p)))
    return out
