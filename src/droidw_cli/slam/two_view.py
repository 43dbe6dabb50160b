"""Two-view initialisation: the relative pose and a depth map from the flow between two keyframes.

Started flat (every pose the identity, every disparity 1), the Gauss-Newton
of the first BA explains a camera walking *into* the scene as one moving
sideways and turning: near the focus of expansion the flow of a forward
translation is small, and a lateral translation plus a rotation produce
nearly the same field over a narrow view (the bas-relief ambiguity of
structure from motion).  On the ``forward`` preset (seed 1) the first
keyframes' heading came out 58° off that way, and the map built on it never
recovered.  ORB-SLAM initialises from a two-view model instead; so does this.

For keyframes a, b with correspondences x_a → x_b on the 1/8 grid (the
cached edge's targets where its confidence is at least ``min_weight``), in
normalised coordinates x̃ = K⁻¹ [x, 1]:

1. the essential matrix E with x̃_bᵀ E x̃_a = 0 by RANSAC (OpenCV's five-point
   solver; threshold ``thresh_px`` grid px), then by least median of squares
   on RANSAC's inliers (RANSAC keeps its best minimal sample: on a synthetic
   0.8 m step with 0.05 grid px of noise its heading erred by up to 5°, the
   refined one by under 1°), decomposed into the (R, t), ‖t‖ = 1, that puts
   most inliers in front of both cameras;
2. each inlier's depth in a by the linear triangulation along its ray,

       z_a = −((x̃_b × R x̃_a) · (x̃_b × t)) / ‖x̃_b × R x̃_a‖²,

   kept where it is positive and the parallax angle, sin θ ≈ ‖x̃_b × R x̃_a‖
   / ‖x̃_b‖ ‖x̃_a‖, is at least ``min_parallax`` radians (near the focus of
   expansion, and on the sky, depth is unobservable from two views);
3. the scale: depths divided by their median (so the median disparity is 1,
   the flat start's level), t likewise; cells without a kept depth take
   disparity 1.

A pair whose inliers are fewer than ``min_inliers`` of its confident cells
(movers fill the view, or the flow failed) gives ``None``: the caller keeps
the flat start.  So does a pair that a homography explains as well: one
that takes at least ``max_homography`` of the essential matrix's inliers
within the same threshold (a turning camera, or a plane, shows no depth, and
the essential matrix of such a pair is ill-posed; ORB-SLAM's initialiser
chooses between the two models likewise), unless the plane is not all there
is: at least MIN_POINTS / 2 inliers lie off it, and they choose the essential
matrix's heading among the motions the homography decomposes into,
H = K (R + t nᵀ/d) K⁻¹ (Faugeras-Lustman; OpenCV's ``decomposeHomographyMat``):
under the one within ``plane_angle_deg`` of it their median epipolar distance
is under half that of the best one heading elsewhere.  A plane seen while
walking along it fits two motions, along it and towards it; points off it
fit only one (the right one by 20-40× on the generator's street), stray
correspondences neither.  A camera looking down at the ground while it
walks along it (a follow shot's view, ``follow-static`` seed 2) showed
95.8 % of 566 inliers on the ground plane and the essential matrix's
heading was 0.4° off the truth, but the pair was refused; the flat start took
the other motion (towards the ground, 74° off), every later keyframe came out
nearer and the scale collapsed (514 cm ATE over 21 m; 3.26 cm with the pair
kept).  ``follow-pan`` seed 1 (98.1 % of 1296 on the plane, 25 off it):
65.40 → 0.81 cm.  A pure plane still gives ``None``.  The real follow shot
``lady-running`` at ``fast`` (66 confident cells; the homography's 95th
percentile transfer error 0.37 grid px) took a spurious translation from it,
dropped from 13 keyframes to 8 and never turned 5° in a window, so
``--calib auto`` estimated no focal length.  The street presets' 95th
percentiles read 2.3-3.4 grid px (``drive`` seeds 1-2) and 2.5-2.9
(``forward``), the rooms' 0.65-1.4 (``walk``, ``stopgo``).  Counting the
homography's own RANSAC inliers among all confident cells instead (ratio to
the essential matrix's inliers ≥ 0.95) took the ``drive`` seed 1 pair
(0.952) for a turn and its heading came out 33° off."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import Tensor

from droidw_cli.geometry.lie import so3_exp_quat

MIN_POINTS = 40


@dataclass(frozen=True)
class TwoView:
    """The pose of keyframe b relative to a (world-to-camera with a's camera as the world, (7,)), a's disparity
    (h, w) with median 1 where it was triangulated, and the share of confident cells that are inliers."""

    pose: Tensor
    disparity: Tensor
    inliers: float
    triangulated: float


def _normalised(x: np.ndarray, y: np.ndarray, k: np.ndarray) -> np.ndarray:
    fx, fy, cx, cy = k
    return np.stack([(x - cx) / fx, (y - cy) / fy], -1)


def _homography(src: np.ndarray, dst: np.ndarray, thresh_px: float) -> tuple[np.ndarray | None, np.ndarray]:
    """The homography src → dst by RANSAC (``thresh_px``) and which points it takes within ``thresh_px``."""
    hom, _ = cv2.findHomography(src, dst, cv2.RANSAC, thresh_px)
    if hom is None:
        return None, np.zeros(len(src), bool)
    moved = cv2.perspectiveTransform(src[None], hom)[0]
    return hom, np.linalg.norm(moved - dst, axis=1) <= thresh_px


def _epipolar_distance(rot: np.ndarray, t: np.ndarray, pa: np.ndarray, pb: np.ndarray) -> np.ndarray:
    """Distance (normalised units) of each x̃_b from the epipolar line of x̃_a under the motion (R, t)."""
    tx = np.array([[0.0, -t[2], t[1]], [t[2], 0.0, -t[0]], [-t[1], t[0], 0.0]])
    lines = np.concatenate([pa, np.ones((len(pa), 1))], 1) @ (tx @ rot).T  # E x̃_a
    xb = np.concatenate([pb, np.ones((len(pb), 1))], 1)
    return np.abs((lines * xb).sum(1)) / np.maximum(np.linalg.norm(lines[:, :2], axis=1), 1e-12)


def _plane_confirms(hom: np.ndarray, k: np.ndarray, t: np.ndarray, pa_off: np.ndarray, pb_off: np.ndarray,
                    max_angle_deg: float) -> bool:
    """Do the points off the plane choose the essential matrix's heading ``t`` among the motions the homography
    ``hom`` (grid px) decomposes into, H = K (R + t' nᵀ/d) K⁻¹ (OpenCV's decomposition, up to sign)?  The motion
    within ``max_angle_deg`` of ``t`` must put them nearer their epipolar lines, by median, than half of what
    the best motion of another heading does (a plane alone fits two motions alike; points off it tell them
    apart, and stray correspondences fit neither)."""
    kmat = np.array([[k[0], 0.0, k[2]], [0.0, k[1], k[3]], [0.0, 0.0, 1.0]])
    _, rotations, translations, _ = cv2.decomposeHomographyMat(hom, kmat)
    unit = t / max(float(np.linalg.norm(t)), 1e-12)
    cos = np.cos(np.radians(max_angle_deg))
    same, other = np.inf, np.inf
    for rot, tp in zip(rotations, translations):
        tp = tp.ravel()
        norm = float(np.linalg.norm(tp))
        if norm < 1e-9:
            continue
        err = float(np.median(_epipolar_distance(rot, tp / norm, pa_off, pb_off)))
        if abs(float(unit @ tp)) / norm >= cos:
            same = min(same, err)
        else:
            other = min(other, err)
    return same < 0.5 * other


def two_view(target: Tensor, weight: Tensor, intrinsics: Tensor, min_weight: float = 0.5, thresh_px: float = 0.5,
             min_parallax: float = 0.01, min_inliers: float = 0.3,
             max_homography: float = 0.95, plane_angle_deg: float = 10.0) -> TwoView | None:
    """Relative pose and disparity of edge (a, b) from its targets (h, w, 2) and confidences (h, w, 2), grid
    intrinsics ``[fx, fy, cx, cy]`` (module docstring); None when the pair does not determine them."""
    h, w = target.shape[:2]
    k = intrinsics.detach().cpu().double().numpy()
    tgt = target.detach().cpu().double().numpy()
    conf = weight.detach().cpu().float().numpy()[..., 0]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    inside = (tgt[..., 0] >= 0) & (tgt[..., 0] <= w - 1) & (tgt[..., 1] >= 0) & (tgt[..., 1] <= h - 1)
    ok = (conf >= min_weight) & inside & np.isfinite(tgt).all(-1)
    if ok.sum() < MIN_POINTS:
        return None
    pa = _normalised(xs[ok], ys[ok], k)
    pb = _normalised(tgt[..., 0][ok], tgt[..., 1][ok], k)
    thresh = thresh_px / float(np.sqrt(k[0] * k[1]))
    e, mask = cv2.findEssentialMat(pa, pb, focal=1.0, pp=(0.0, 0.0), method=cv2.RANSAC, prob=0.999,
                                   threshold=thresh)
    if e is None or e.shape != (3, 3):
        return None
    first = mask.ravel() > 0
    if first.sum() >= MIN_POINTS:  # least median of squares on RANSAC's inliers: its estimate is a minimal sample's
        refined, _ = cv2.findEssentialMat(pa[first], pb[first], focal=1.0, pp=(0.0, 0.0), method=cv2.LMEDS)
        if refined is not None and refined.shape == (3, 3):
            e = refined
    count, rot, t, mask = cv2.recoverPose(e, pa, pb, focal=1.0, pp=(0.0, 0.0), mask=mask)
    inl = mask.ravel() > 0
    if count < MIN_POINTS or count < min_inliers * ok.sum():
        return None
    t = t.ravel()
    hom, on_plane = _homography(np.stack([xs[ok], ys[ok]], -1)[inl], tgt[ok][inl], thresh_px)
    if hom is not None and float(np.mean(on_plane)) >= max_homography:
        off = np.flatnonzero(inl)[~on_plane]
        if len(off) < MIN_POINTS // 2 or not _plane_confirms(hom, k, t, pa[off], pb[off], plane_angle_deg):
            return None  # a turn, or a plane alone: the essential matrix is ill-posed
    ra = np.concatenate([pa, np.ones((len(pa), 1))], 1) @ rot.T  # R x̃_a
    xb = np.concatenate([pb, np.ones((len(pb), 1))], 1)
    cross_r, cross_t = np.cross(xb, ra), np.cross(xb, t)
    norm2 = (cross_r * cross_r).sum(1)
    z = -(cross_r * cross_t).sum(1) / np.maximum(norm2, 1e-18)
    sin_par = np.sqrt(norm2) / (np.linalg.norm(xb, axis=1) * np.linalg.norm(ra, axis=1))
    good = inl & (z > 0) & (sin_par >= min_parallax)
    if good.sum() < MIN_POINTS:
        return None
    scale = float(np.median(z[good]))
    disp = np.ones((h, w), np.float32)
    cells = np.flatnonzero(ok.ravel())[good]
    disp.ravel()[cells] = (scale / z[good]).astype(np.float32)
    rvec, _ = cv2.Rodrigues(rot)
    quat = so3_exp_quat(torch.from_numpy(rvec.ravel()).float())
    pose = torch.cat([torch.from_numpy(t / scale).float(), quat])
    return TwoView(pose, torch.from_numpy(disp), float(count) / float(ok.sum()), float(good.sum()) / (h * w))
