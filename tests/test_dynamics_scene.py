"""Scene-consistency dynamic detection on an exact toy scene.

A textured fronto-parallel plane at z = 3 m seen by K = 5 cameras moving
sideways (with small rotations), and a textured square at z = 1.5 m that
moves between frames.  Colour, depth and the square's mask are ray-cast
exactly at the pixel centres.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics import DetectionParams, detect_dynamic, detect_frame, inconsistency, predict_views
from droidw_cli.io.trajectory import tq_from_pose

H, W = 48, 64
INTR = np.array([50.0, 50.0, 31.5, 23.5])
K = 5
PLANE_Z, SQUARE_Z, SIDE = 3.0, 1.5, 0.5


def _rot(ax: float, ay: float) -> np.ndarray:
    cx, sx, cy, sy = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    return ry @ rx


def _plane_tex(x, y):
    r = 0.5 + 0.3 * np.sin(2 * np.pi * x / 0.5) * np.cos(2 * np.pi * y / 0.6)
    g = 0.5 + 0.3 * np.cos(2 * np.pi * (x + y) / 0.7)
    b = 0.4 + 0.2 * np.sin(2 * np.pi * y / 0.45 + 1.0)
    return np.stack((r, g, b), -1)


def _square_tex(u, v):
    r = 0.85 + 0.1 * np.sin(2 * np.pi * u / 0.2)
    g = 0.2 + 0.1 * np.cos(2 * np.pi * v / 0.2)
    return np.stack((r, g, np.full_like(r, 0.15)), -1)


def _camera(k: int):
    """(R_c2w, centre) of camera k: sideways translation, small rotations."""
    return _rot(0.01 * (k - 2), -0.015 * (k - 2)), np.array([0.1 * k, 0.02 * k, 0.0])


def _square_origin(k: int, moving: bool = True) -> np.ndarray:
    """World (x, y) of the square's lower corner in frame k (moves 0.3 m/frame right, 0.05 m/frame down)."""
    k = k if moving else 2
    return np.array([-0.2 + 0.3 * (k - 2), -0.25 + 0.05 * (k - 2)])


def _inside_square(x, y, k, moving: bool = True):
    o = _square_origin(k, moving)
    return (x >= o[0]) & (x <= o[0] + SIDE) & (y >= o[1]) & (y <= o[1] + SIDE)


def render(with_square: bool = True, moving: bool = True):
    """Images (K, H, W, 3), depth (K, H, W), square masks (K, H, W), w2c poses (K, 7), world plane hits."""
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    ray = np.stack(((u - INTR[2]) / INTR[0], (v - INTR[3]) / INTR[1], np.ones_like(u)), -1)
    imgs, depths, masks, poses, hits = [], [], [], [], []
    for k in range(K):
        r, c = _camera(k)
        d = ray @ r.T  # world directions whose camera z-component is 1 → λ is the z-depth
        lam_p = (PLANE_Z - c[2]) / d[..., 2]
        p = c + lam_p[..., None] * d
        img, depth = _plane_tex(p[..., 0], p[..., 1]), lam_p.copy()
        lam_s = (SQUARE_Z - c[2]) / d[..., 2]
        s = c + lam_s[..., None] * d
        sq = _inside_square(s[..., 0], s[..., 1], k, moving) if with_square else np.zeros((H, W), bool)
        o = _square_origin(k, moving)
        img[sq] = _square_tex(s[..., 0] - o[0], s[..., 1] - o[1])[sq]
        depth[sq] = lam_s[sq]
        t, q = tq_from_pose(np.linalg.inv(np.block([[r, c[:, None]], [np.zeros((1, 3)), np.ones((1, 1))]]))[None])
        imgs.append(img), depths.append(depth), masks.append(sq), hits.append(p)
        poses.append(np.concatenate((t[0], q[0])))
    return (torch.tensor(np.array(imgs), dtype=torch.float32), torch.tensor(np.array(depths), dtype=torch.float32),
            np.array(masks), torch.tensor(np.array(poses), dtype=torch.float32), np.array(hits))


@pytest.fixture(scope="module")
def scene():
    return render(True)


def _iou(a, b) -> float:
    a, b = np.asarray(a, bool), np.asarray(b, bool)
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_predictions_reproduce_static_plane():
    imgs, depth, _, poses, hits = render(False)
    pred_rgb, pred_disp, valid = predict_views(imgs, 1.0 / depth, poses, torch.tensor(INTR, dtype=torch.float32),
                                               2, [0, 1, 3, 4])
    assert pred_rgb.shape == (4, H, W, 3) and pred_disp.shape == (4, H, W) and valid.dtype == torch.bool
    assert valid.float().mean() > 0.8
    cerr = (pred_rgb - imgs[2]).norm(dim=-1)[valid]
    assert cerr.median() < 0.03 and cerr.max() < 0.06  # bilinear interpolation error only
    assert (imgs[0] - imgs[2]).norm(dim=-1).median() > 0.1  # the unwarped neighbour is far off
    derr = (1.0 / pred_disp[valid] - depth[2].expand(4, H, W)[valid]).abs()
    assert derr.max() < 1e-3
    # validity = the plane point of each target pixel projects inside the source (independent numpy projection)
    for s, j in enumerate((0, 1, 3, 4)):
        r, c = _camera(j)
        pc = (hits[2] - c) @ r
        u, v = INTR[0] * pc[..., 0] / pc[..., 2] + INTR[2], INTR[1] * pc[..., 1] / pc[..., 2] + INTR[3]
        inside = (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
        assert (valid[s].numpy() != inside).sum() <= 2 and (~inside).sum() > 20


def test_predict_views_rejects_bad_input(scene):
    imgs, depth, _, poses, _ = scene
    intr = torch.tensor(INTR, dtype=torch.float32)
    with pytest.raises(ValueError):
        predict_views(imgs[..., :2], 1.0 / depth, poses, intr, 2, [1])
    with pytest.raises(ValueError):
        predict_views(imgs, 1.0 / depth, poses[:3], intr, 2, [1])
    with pytest.raises(ValueError):
        predict_views(imgs, 1.0 / depth, poses, intr, 2, [7])
    rgb, disp, valid = predict_views(imgs, 1.0 / depth, poses, intr, 2, [])
    assert rgb.shape == (0, H, W, 3) and not valid.any()


def test_moving_square_detected(scene):
    imgs, depth, masks, poses, _ = scene
    det = detect_frame(imgs, 1.0 / depth, poses, torch.tensor(INTR, dtype=torch.float32), 2, [0, 1, 3, 4])
    iou = _iou(det.mask.numpy(), masks[2])
    assert iou >= 0.7, iou
    assert det.objects.count == 1
    cx, cy = det.objects.centres[0].tolist()
    assert masks[2][int(round(cy)), int(round(cx))]  # inscribed-circle centre lies on the square
    out = detect_dynamic(imgs, 1.0 / depth, poses, INTR, DynamicsConfig(), radius=2)
    assert out.shape == (K, H, W) and out.dtype == torch.bool
    assert _iou(out[2].numpy(), masks[2]) >= 0.7
    assert min(_iou(out[k].numpy(), masks[k]) for k in range(K)) >= 0.5


def test_detection_survives_moderate_noise(scene):
    imgs, depth, masks, poses, _ = scene
    g = torch.Generator().manual_seed(0)
    noisy_imgs = imgs + 0.02 * torch.randn(imgs.shape, generator=g)
    noisy_depth = depth * (1 + 0.01 * torch.randn(depth.shape, generator=g))
    noisy_poses = poses.clone()
    noisy_poses[:, :3] += 0.005 * torch.randn(K, 3, generator=g)
    out = detect_dynamic(noisy_imgs, 1.0 / noisy_depth, noisy_poses, INTR, DynamicsConfig(), radius=2)
    assert _iou(out[2].numpy(), masks[2]) >= 0.7
    assert torch.equal(out, detect_dynamic(noisy_imgs, 1.0 / noisy_depth, noisy_poses, INTR, DynamicsConfig()))


def test_single_keyframe_gives_empty_mask(scene):
    imgs, depth, _, poses, _ = scene
    out = detect_dynamic(imgs[:1], 1.0 / depth[:1], poses[:1], INTR)
    assert out.shape == (1, H, W) and not out.any()
    with pytest.raises(ValueError):
        detect_dynamic(imgs, 1.0 / depth, poses, INTR, radius=0)


def test_static_scene_has_no_dynamics():
    imgs, depth, _, poses, _ = render(False)
    out = detect_dynamic(imgs, 1.0 / depth, poses, INTR, DynamicsConfig(), radius=2)
    assert out.float().mean() < 0.01


def test_static_occluder_edges_are_not_dynamic():
    # a square that stays put: parallax at its edges only (disoccluded background, blended grid disparities)
    imgs, depth, masks, poses, _ = render(True, moving=False)
    assert masks[2].sum() > 200
    intr = torch.tensor(INTR, dtype=torch.float32)
    det = detect_frame(imgs, 1.0 / depth, poses, intr, 2, [0, 1, 3, 4])
    assert det.maps.m_ic.any()  # the edges are inconsistent …
    assert not det.maps.m_dyn.any() and not det.mask.any()  # … but not dynamic
    # ADD-SLAM's plain rule on blended bilinear depths does flag edge pixels of the static square
    plain = DetectionParams(depth_mode="bilinear", sign_margin=0.0)
    assert detect_frame(imgs, 1.0 / depth, poses, intr, 2, [0, 1, 3, 4], params=plain).maps.m_dyn.sum() >= 5


def test_uncovered_background_is_not_dynamic(scene):
    imgs, depth, masks, poses, hits = scene
    # target-2 plane pixels hidden by the square in source j: the segment to camera j crosses the square
    uncovered = np.zeros((H, W), bool)
    for j in (0, 1, 3, 4):
        _, c = _camera(j)
        a = (SQUARE_Z - c[2]) / (hits[2][..., 2] - c[2])
        s = c + a[..., None] * (hits[2] - c)
        uncovered |= _inside_square(s[..., 0], s[..., 1], j)
    uncovered &= ~masks[2]
    assert uncovered.sum() > 100
    det = detect_frame(imgs, 1.0 / depth, poses, torch.tensor(INTR, dtype=torch.float32), 2, [0, 1, 3, 4])
    ic_any = det.maps.m_ic.any(0).numpy()
    assert ic_any[uncovered].mean() > 0.9  # inconsistent …
    signed = det.maps.signed_depth.numpy()
    assert (signed.max(0)[uncovered] > 1.0).mean() > 0.9  # … but farther than predicted
    assert not det.maps.m_dyn_views.numpy()[:, uncovered].any()
    assert det.mask.numpy()[uncovered].mean() < 0.02


def test_thresholds_scale_with_median(scene):
    imgs, depth, _, poses, _ = scene
    disp = 1.0 / depth
    pred_rgb, pred_disp, valid = predict_views(imgs, disp, poses, torch.tensor(INTR, dtype=torch.float32), 2,
                                               [0, 1, 3, 4])
    params = DetectionParams(color_floor=0.0, depth_floor=0.0)
    a = inconsistency(imgs[2], disp[2], pred_rgb, pred_disp, valid, 20.0, params)
    # every colour and depth error doubled: colours ×2, depths ×2 (disparities ÷2)
    b = inconsistency(2 * imgs[2], disp[2] / 2, 2 * pred_rgb, pred_disp / 2, valid, 20.0, params)
    assert a.m_dyn.any() and a.m_ic.any()
    assert torch.allclose(b.tau_color, 2 * a.tau_color) and torch.allclose(b.tau_depth, 2 * a.tau_depth)
    assert torch.equal(a.m_ic, b.m_ic) and torch.equal(a.m_dyn, b.m_dyn)
    # τ is tau_scale × the median of the valid errors
    med = a.color_err[0][a.valid[0]].median()
    assert torch.isclose(a.tau_color[0], 20.0 * med)
    # a larger scale raises τ_I and flags fewer colour outliers
    c = inconsistency(imgs[2], disp[2], pred_rgb, pred_disp, valid, 60.0, params)
    assert torch.allclose(c.tau_color, 3 * a.tau_color)
    flagged = lambda m: (m.color_err > m.tau_color.view(-1, 1, 1)).sum()  # noqa: E731
    assert flagged(c) < flagged(a)


def test_inconsistency_rejects_bad_input(scene):
    imgs, depth, _, poses, _ = scene
    disp = 1.0 / depth
    pred_rgb, pred_disp, valid = predict_views(imgs, disp, poses, torch.tensor(INTR, dtype=torch.float32), 2, [1, 3])
    with pytest.raises(ValueError):
        inconsistency(imgs[2], disp[2], pred_rgb[:1], pred_disp, valid)
    with pytest.raises(ValueError):
        inconsistency(imgs[2], disp[2], pred_rgb, pred_disp, valid, tau_scale=0.0)
    # a pixel with no valid view is never dynamic, and a view with no valid pixel gets τ = inf
    m = inconsistency(imgs[2], disp[2], pred_rgb, pred_disp, torch.zeros_like(valid))
    assert not m.m_dyn.any() and torch.isinf(m.tau_color).all()
