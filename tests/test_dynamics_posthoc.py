"""Monocular output masks (dynamics/posthoc.py) and the kept short edges of KeyframeMasks."""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics.inloop import EDGE_SPAN, KeyframeMasks
from droidw_cli.dynamics.posthoc import MotionParams, keyframe_mask, motion_distance, motion_masks

H, W = 24, 32
KK = np.array([30.0, 30.0, 15.5, 11.5])


def _rot(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _static_targets(depth: np.ndarray, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
    """Where each grid pixel of camera k with this depth lands in camera j (X_j = R X_k + t)."""
    fx, fy, cx, cy = KK
    gy, gx = np.meshgrid(np.arange(H, dtype=np.float64), np.arange(W, dtype=np.float64), indexing="ij")
    pts = np.stack([(gx - cx) / fx, (gy - cy) / fy, np.ones_like(gx)], -1) * depth[..., None]
    q = pts @ rot.T + trans
    return np.stack([fx * q[..., 0] / q[..., 2] + cx, fy * q[..., 1] / q[..., 2] + cy], -1)


def test_static_pixels_have_zero_distance_whatever_their_depth():
    rng = np.random.default_rng(0)
    depth = rng.uniform(1.0, 6.0, (H, W))
    rot, trans = _rot(0.05), np.array([0.2, 0.05, 0.1])
    target = _static_targets(depth, rot, trans)
    dist = motion_distance(target, rot, trans, KK, rho_max=3.0)
    assert dist.max() < 0.05
    # a pixel moved across its epipolar line by 1 px is 1 px away (the line is locally straight)
    d0 = motion_distance(target + np.array([0.0, 1.0]), rot, trans, KK, rho_max=3.0)
    assert np.median(d0) > 0.3


def test_pure_rotation_flags_any_residual_motion():
    rot, trans = _rot(0.08), np.zeros(3)
    target = _static_targets(np.full((H, W), 2.0), rot, trans)
    assert motion_distance(target, rot, trans, KK, rho_max=3.0).max() < 1e-6
    moved = target.copy()
    moved[5:10, 5:10] += np.array([1.5, 0.0])  # along what would be an epipolar line: still caught
    dist = motion_distance(moved, rot, trans, KK, rho_max=3.0)
    assert np.allclose(dist[5:10, 5:10], 1.5, atol=1e-6)
    assert dist[15:, 15:].max() < 1e-6


def test_keyframe_mask_keeps_blobs_and_drops_thin_lines():
    p = MotionParams(min_seed=0)  # every unconfident blob counts (the support test is below)
    weights = np.ones((2, H, W))
    weights[:, 4:12, 4:10] = 0.0  # a mover with no confident flow on any edge
    weights[:, 18, :] = 0.0  # an occlusion edge: one cell thick
    scores = np.zeros((2, H, W))
    scores[0, 5:9, 20:26] = 3.0  # a mover with confident flow across its epipolar lines
    mask = keyframe_mask(scores, weights, p)
    assert mask[4:12, 4:10].all() and mask[5:9, 20:26].all()
    assert not mask[18].any()
    assert mask.sum() == 8 * 6 + 4 * 6
    assert not keyframe_mask(np.zeros((0, H, W)), np.zeros((0, H, W)), p).any()


def _w2c(rot: np.ndarray, trans: np.ndarray) -> torch.Tensor:
    """(7,) world-to-camera pose [t, q(xyzw)] of a camera with X_cam = R X_world + t."""
    from scipy.spatial.transform import Rotation

    return torch.tensor([*trans, *Rotation.from_matrix(rot).as_quat()], dtype=torch.float64)


def test_motion_masks_find_a_moving_square_under_the_final_poses():
    rng = np.random.default_rng(1)
    depth = rng.uniform(2.0, 4.0, (H, W))
    rot, trans = _rot(0.03), np.array([0.15, 0.0, 0.02])
    poses = torch.stack([_w2c(np.eye(3), np.zeros(3)), _w2c(rot, trans)])
    target = _static_targets(depth, rot, trans)
    target[8:16, 10:18] += np.array([0.0, 2.0])  # the mover walks down by 2 cells
    edges = {(0, 1): (target.astype(np.float16), np.full((H, W), 255, np.uint8))}
    back = _static_targets(depth, rot.T, -rot.T @ trans)  # the reverse edge of the static scene, no mover
    edges[(1, 0)] = (back.astype(np.float16), np.full((H, W), 255, np.uint8))
    disps = torch.from_numpy(1.0 / depth).float().expand(2, H, W)
    masks = motion_masks(edges, poses, disps, torch.from_numpy(KK))
    truth = np.zeros((H, W), bool)
    truth[8:16, 10:18] = True
    m = masks[0].numpy()
    assert (m & truth).sum() / (m | truth).sum() > 0.8
    assert not masks[1].numpy().any()


def test_keyframe_masks_keep_short_edges_and_renumber_on_removal():
    km = KeyframeMasks(DynamicsConfig(), (H, W), consistency=False, keep_flow=True)
    for _ in range(5):
        km.append(np.zeros((H * 8, W * 8, 3), np.uint8))
    target, weight = torch.zeros(H, W, 2), torch.ones(H, W, 2)
    for i, j in [(0, 1), (1, 3), (3, 1), (0, 0 + EDGE_SPAN + 1), (3, 4)]:
        km.keep_edge(i, j, target, weight)
    assert set(km.edges) == {(0, 1), (1, 3), (3, 1), (3, 4)}
    assert km.edges[(0, 1)][1].dtype == np.uint8 and int(km.edges[(0, 1)][1].max()) == 255
    km.remove(1)
    assert set(km.edges) == {(2, 3)}
    assert len(km) == 4
    off = KeyframeMasks(DynamicsConfig(), (H, W), consistency=False)  # RGB-D or consistency: nothing kept
    off.append(np.zeros((H * 8, W * 8, 3), np.uint8))
    off.keep_edge(0, 1, target, weight)
    assert not off.edges


def test_finalise_turns_the_edges_of_settled_keyframes_into_masks_and_drops_them():
    """Archived keyframes (global BA horizon) get their mask at once: memory stays bounded, masks equal."""
    rng = np.random.default_rng(2)
    depth = rng.uniform(2.0, 4.0, (H, W))
    rot, trans = _rot(0.03), np.array([0.15, 0.0, 0.02])
    poses = torch.stack([_w2c(np.eye(3), np.zeros(3)), _w2c(rot, trans), _w2c(rot @ rot, 2 * trans)])
    disps = torch.from_numpy(1.0 / depth).float().expand(3, H, W)
    km = KeyframeMasks(DynamicsConfig(), (H, W), consistency=False, keep_flow=True)
    for _ in range(3):
        km.append(np.zeros((H * 8, W * 8, 3), np.uint8))
    target = _static_targets(depth, rot, trans)
    target[8:16, 10:18] += np.array([0.0, 2.0])
    full = torch.ones(H, W)
    for i, j in [(0, 1), (1, 2), (2, 1)]:
        km.keep_edge(i, j, torch.from_numpy(target).float(), full)
    expected = motion_masks(dict(km.edges), poses, disps, torch.from_numpy(KK))
    km.finalise(1, poses, disps, torch.from_numpy(KK))
    assert len(km.final) == 1 and set(km.edges) == {(1, 2), (2, 1)}
    km.keep_edge(0, 2, torch.from_numpy(target).float(), full)  # a settled keyframe takes no new edges
    assert (0, 2) not in km.edges
    out = km.output_masks(poses, disps, torch.from_numpy(KK))
    assert len(out) == 3 and not km.edges
    for a, b in zip(out, expected):
        assert torch.equal(a, b)
    assert out[0][8:16, 10:18].float().mean() > 0.8


def test_unconfident_cells_join_the_mask_only_where_the_geometry_sees_motion():
    """An unconfident blob with a few cells that move across their epipolar lines is a mover, kept whole;
    one without (blur, a textureless wall) is not; min_seed 0 keeps both."""
    weights = np.ones((2, H, W))
    weights[:, 4:12, 4:10] = 0.0  # a mover: no confident flow ...
    scores = np.zeros((2, H, W))
    scores[0, 9:12, 6:9] = 3.0  # ... except a few cells, which the geometry rejects
    weights[:, 16:22, 20:28] = 0.0  # static but unconfident
    mask = keyframe_mask(scores, weights, MotionParams())
    assert mask[4:12, 4:10].all()
    assert not mask[16:22, 20:28].any()
    assert keyframe_mask(scores, weights, MotionParams(min_seed=0))[16:22, 20:28].all()
