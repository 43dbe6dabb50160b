"""Where an edge's flow starts: the motion filter's flow, or the map's prediction.

DIS finds motions of a few tens of pixels on its own; a camera travelling
into the scene at 10 frames/s moves the near road and facades by far more
between keyframes, and DIS needs a start there (:func:`~droidw_cli.correspondence.dis.calc_warped`).
Each new edge (i, j) gets the first of these that exists:

1. **adjacent pairs**: the motion filter's flow between the two, when one was
   the other's reference (it was measured frame by frame, each frame started
   from the last: :mod:`droidw_cli.slam.motion_filter`), brought to the
   working size (:func:`adjacent_start`); none where the motion filter kept
   no flow (a motion DIS finds alone), as the scout matches them ahead
   (:mod:`droidw_cli.slam.scout`: the same bytes either way).  Where what
   that flow shows beyond a rotation is small enough for DIS to find alone
   (``frontend.rotation_start``), the start is only the rotation that best
   explains it (:func:`rotation_start`);
2. **wider pairs**: the flow the current poses and disparities induce (Eq. 1).

A start from the map carries the map's scale into the measurement (the
warped DIS keeps a few per cent of a start's error).  Starting wider pairs
instead from a chain of two matched edges, p*_ij(x) = p*_mj(p*_im(x)), which
knows nothing of the map, was tried and left out: on seeds 1-3 it moved ATE
(% of the path) of ``forward``/``ride``/``drive`` from 0.059/0.071/0.107 to
0.044/0.042/0.107 (links gated at confidence 0.2), within the seed-to-seed
spread, and doubled it on ``rotate`` (seeds 1 and 3: 0.77 → 1.42 cm and
0.50 → 0.82 cm).

**Why a rotation alone** (``frontend.rotation_start``).  DIS's error grows
with the flow it measures, and a panning camera's flow between keyframes is
mostly its rotation (20-30 px against a few px of parallax), so a small
share of the rotation's flow is a large share of the parallax that holds the
scale.  On the follow shot's path through an empty street (``follow-static``
seed 1) the scale grew 4 % along the walk (5.18 cm ATE over 19.6 m).  The
tracker with its keyframe edges' DIS started from the true flow read 0.75 cm;
with only the adjacent pairs started from the true *rotation* 1.24 cm (on
seed 2 1.84 cm, and 1.11 / 2.03 cm with the rotation 2 % too large / 5 % too
small), so the start need not be exact, only smooth and free of the
translation.  Started from the
rotation fitted to the motion filter's flow (:func:`fit_rotation`, which
absorbs a little of a sideways step) it reads 0.93 cm.  Where the rotation
takes less than a quarter of the flow (:data:`ROTATION_SHARE`; a car driving
on) or more than ``rotation_start`` grid px are left, the whole flow still starts
DIS: the expansion of a camera travelling into the scene is beyond what DIS
finds alone (``drive`` seed 1: 6.47 → 16.67 cm with a rotation start
wherever under 4 grid px were left).  A flow small enough to be DIS's initial flow
(under :data:`~droidw_cli.correspondence.dis.WARP_MIN`, not warped out: DIS then
searches again at every level) stays whole.  On ``follow-static`` seed 1 the starts
taken average 13-16 px a component (warped), on ``wobble`` seed 1, a near-still
camera, 4-10 px; there the rotation start had read 0.35 cm against 0.30 without
it, and with this gate 0.28 (docs/benchmarks.md).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from droidw_cli.correspondence.confidence import invert_flow
from droidw_cli.correspondence.dis import warped_out
from droidw_cli.correspondence.grid import BLOCK, mean_length
from droidw_cli.geometry.camera import scale_intrinsics


def adjacent_start(flow_half: np.ndarray, size: tuple[int, int], invert: bool, intrinsics: np.ndarray | None = None,
                   max_rest: float = 0.0) -> np.ndarray:
    """The motion filter's half-size flow a → b (:attr:`~droidw_cli.slam.motion_filter.MotionFilter.accepted_flow`)
    at the working size ``size`` (H, W), as the start of the flow a → b, or of b → a with ``invert``; with
    ``intrinsics`` (working size) and ``max_rest`` > 0, its rotation alone where :func:`rotation_start` says."""
    scale = np.float32(size[1] / flow_half.shape[1])
    full = cv2.resize(flow_half, (size[1], size[0]), interpolation=cv2.INTER_LINEAR) * scale
    full = invert_flow(full) if invert else np.ascontiguousarray(full, dtype=np.float32)
    if intrinsics is None or max_rest <= 0:
        return full
    return rotation_start(full, intrinsics, max_rest)


class AdjacentStart:
    """:func:`adjacent_start` with one tracker's settings: ``max_rest`` (``frontend.rotation_start``, grid px) and the
    working-size intrinsics of the first grid intrinsics ``intrinsics8``, so that a start made on another
    thread (:mod:`droidw_cli.slam.scout`) does not depend on when a focal estimate came."""

    def __init__(self, intrinsics8, max_rest_grid: float):
        k8 = np.asarray([float(v) for v in intrinsics8], dtype=np.float64)
        self.intrinsics = scale_intrinsics(k8, 1.0 / BLOCK)
        self.max_rest = float(max_rest_grid) * BLOCK  # working px

    def __call__(self, flow_half: np.ndarray, size: tuple[int, int], invert: bool) -> np.ndarray:
        return adjacent_start(flow_half, size, invert, self.intrinsics, self.max_rest)


def _rotate(rays: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised image points of the rays (N, 3) turned by ``rot``, and the rotated rays."""
    q = rays @ rot.T
    return q[:, :2] / q[:, 2:3], q


def fit_rotation(flow: np.ndarray, intrinsics: np.ndarray, stride: int = 8, iters: int = 4,
                 sigma_px: float = 2.0) -> np.ndarray:
    """The rotation R (3×3) whose flow π(K R K⁻¹ x) − x best explains ``flow`` (H, W, 2), working px.

    Gauss-Newton on R ← exp([ω]×) R over every ``stride``-th pixel, from the identity: with q = R x̄ the
    point moves to (q₀/q₂, q₁/q₂) and ∂(q₀/q₂, q₁/q₂)/∂ω = [[1/q₂, 0, −q₀/q₂²], [0, 1/q₂, −q₁/q₂²]]·(−[q]×).
    Residuals in normalised coordinates are Cauchy-weighted with σ = ``sigma_px`` / fx, so the
    translation's parallax and movers, which no rotation explains, pull less.
    """
    h, w = flow.shape[:2]
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    ys, xs = np.mgrid[stride // 2:h:stride, stride // 2:w:stride].astype(np.float64)
    f = flow[stride // 2::stride, stride // 2::stride].reshape(-1, 2).astype(np.float64)
    xs, ys = xs.reshape(-1), ys.reshape(-1)
    rays = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones_like(xs)], -1)
    goal = np.stack([(xs + f[:, 0] - cx) / fx, (ys + f[:, 1] - cy) / fy], -1)
    sigma2 = (sigma_px / fx) ** 2
    rot = np.eye(3)
    for _ in range(iters):
        p, q = _rotate(rays, rot)
        r = goal - p
        inv = 1.0 / q[:, 2]
        dp = np.zeros((len(q), 2, 3))
        dp[:, 0, 0] = dp[:, 1, 1] = inv
        dp[:, 0, 2], dp[:, 1, 2] = -q[:, 0] * inv * inv, -q[:, 1] * inv * inv
        skew = np.zeros((len(q), 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -q[:, 2], q[:, 1], -q[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = q[:, 2], -q[:, 1], q[:, 0]
        jac = -dp @ skew  # (N, 2, 3)
        wgt = 1.0 / (1.0 + (r * r).sum(1) / sigma2)
        jw = jac * wgt[:, None, None]
        omega = np.linalg.solve(np.einsum("nki,nkj->ij", jw, jac) + 1e-9 * np.eye(3), np.einsum("nki,nk->i", jw, r))
        rot = cv2.Rodrigues(omega.reshape(3, 1))[0] @ rot
    return rot


def rotation_flow(rot: np.ndarray, intrinsics: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """The flow (H, W, 2) float32, working px, of the rotation ``rot``: π(K R K⁻¹ x) − x (rows and columns
    broadcast, in float64)."""
    h, w = size
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    xs, ys = np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64)
    xbar, ybar = ((xs - cx) / fx)[None, :], ((ys - cy) / fy)[:, None]
    q = [rot[i, 0] * xbar + rot[i, 1] * ybar + rot[i, 2] for i in range(3)]
    out = np.empty((h, w, 2), np.float32)
    out[..., 0] = q[0] / q[2] * fx + cx - xs[None, :]
    out[..., 1] = q[1] / q[2] * fy + cy - ys[:, None]
    return out


#: a rotation start needs the rotation to take at least a quarter of the flow: where it takes less (a car
#: driving on, 0.99-1.00 of the flow left on ``drive``) it would be no start, and the expansion is the start's job
ROTATION_SHARE = 0.75


def rotation_start(flow: np.ndarray, intrinsics: np.ndarray, max_rest: float) -> np.ndarray:
    """The flow of the rotation that best explains ``flow`` (:func:`fit_rotation`), when what is left of
    ``flow`` beyond it averages under ``max_rest`` working px (DIS finds that alone) and under
    ``ROTATION_SHARE`` of the flow's own mean; else ``flow``.  A flow DIS would take as its initial flow
    (:func:`~droidw_cli.correspondence.dis.warped_out` false) stays whole."""
    if not warped_out(flow):
        return flow
    rot = fit_rotation(flow, intrinsics)
    turned = rotation_flow(rot, intrinsics, flow.shape[:2])
    rest = mean_length(flow - turned)
    whole = mean_length(flow)
    return turned if rest < max_rest and rest < ROTATION_SHARE * whole else flow


def induced_start(flow_grid: torch.Tensor, valid: torch.Tensor, size: tuple[int, int]) -> np.ndarray:
    """The flow (h, w, 2) in grid px that the poses and disparities induce (zero where not ``valid``), at the
    working size ``size`` (H, W) in its pixels, as the start of an edge's flow."""
    f = torch.where(valid[..., None], flow_grid, torch.zeros_like(flow_grid)).numpy() * 8.0
    return cv2.resize(np.ascontiguousarray(f), (size[1], size[0]), interpolation=cv2.INTER_LINEAR)
