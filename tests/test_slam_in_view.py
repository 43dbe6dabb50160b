"""The cells of a keyframe that another keyframe sees under the current poses and disparities."""

from __future__ import annotations

import types

import numpy as np
import torch

from droidw_cli.slam.keyframe_maps import KeyframeMaps

H, W = 12, 16


class _Buffer(types.SimpleNamespace):
    def __len__(self) -> int:
        return len(self.poses)


class _Maps(KeyframeMaps):
    def __init__(self, poses: torch.Tensor, disps: torch.Tensor):
        self.buffer = _Buffer(poses=poses, disps=disps, grid=(H, W), device=poses.device)
        self.shared = types.SimpleNamespace(intrinsics=torch.tensor([10.0, 10.0, 7.5, 5.5]))
        self.params = types.SimpleNamespace(min_depth=0.05)


def _pose(t):
    p = torch.zeros(7)
    p[:3] = torch.tensor(t, dtype=torch.float32)
    p[6] = 1.0
    return p


def test_a_sideways_step_loses_the_columns_it_leaves_behind_and_a_step_back_loses_none():
    # world-to-camera: camera 1 centred at x = 0.5 (t = −c), camera 2 stepped back by 1 along the optical axis
    poses = torch.stack([_pose([0, 0, 0]), _pose([-0.5, 0, 0]), _pose([0, 0, 1.0])])
    disps = torch.ones(3, H, W)  # every point 1 m in front of camera 0
    side, back = _Maps(poses, disps).in_view(0, [1, 2])
    # x' = x − fx · 0.5 = x − 5: the cells of columns 0-4 land left of −½
    assert not side[:, :5].any() and side[:, 5:].all()
    assert back.all()


def test_points_behind_the_other_camera_are_not_seen():
    poses = torch.stack([_pose([0, 0, 0]), _pose([0, 0, -2.0])])  # camera 1 two metres ahead, past the points
    assert not _Maps(poses, torch.ones(2, H, W)).in_view(0, [1])[0].any()


def test_a_measured_target_inside_the_view_keeps_the_cell_seen():
    poses = torch.stack([_pose([0, 0, 0]), _pose([-0.5, 0, 0])])
    maps = _Maps(poses, torch.ones(2, H, W))
    gy, gx = torch.meshgrid(torch.arange(H, dtype=torch.float32), torch.arange(W, dtype=torch.float32), indexing="ij")
    target = torch.stack([gx - 5, gy], -1)  # the flow agrees with the map: columns 0-4 leave the view
    target[3, 2] = torch.tensor([2.0, 3.0])  # a mover's correspondence stays in view
    seen = maps.in_view(0, [1], [target])[0]
    left = np.zeros((H, 5), dtype=bool)
    left[3, 2] = True
    assert (seen[:, :5] == left).all() and seen[:, 5:].all()
    assert not maps.in_view(0, [1])[0][3, 2]  # by the map alone it leaves the view


def _frontend_with_a_step_aside(in_view: bool):
    """Keyframe 0, keyframe 1 a long step aside (its first 5 columns leave the view, by the map and the flow),
    keyframe 2 a short one; the long edge's Sampson map reads 5 px where its cells leave the view, and at one
    mover cell there whose measured target stays in view; the short edge flags one mover."""
    import dataclasses

    from droidw_cli.ba.registry import get_backend
    from droidw_cli.config import load_config
    from droidw_cli.slam.frontend import Frontend
    from test_slam_backend import _NoMatch

    cfg = load_config("default", [f"dynamics.epipolar_in_view={str(in_view).lower()}", "dynamics.epipolar_dilate=0"])
    fe = Frontend(cfg, dataclasses.replace(cfg.ba, optimize_focal="none"), get_backend("cpu"), _NoMatch(),
                  (H, W), torch.tensor([10.0, 10.0, 7.5, 5.5]), 1)
    image = np.full((H * 8, W * 8, 3), 128, np.uint8)
    for k, pose in enumerate([_pose([0, 0, 0]), _pose([-0.5, 0, 0]), _pose([-0.05, 0, 0])]):
        fe.buffer.append(k, k / 30.0, pose, torch.ones(H, W), image[::8, ::8], torch.zeros(1, H, W))
        fe.masks.append(image, k / 30.0)
    fe.initialised = True
    rng = np.random.default_rng(1)
    maps = {(0, 1): rng.uniform(0, 0.1, (H, W)).astype(np.float32), (0, 2): rng.uniform(0, 0.1, (H, W)).astype(np.float32)}
    maps[0, 1][:, :5] = 5.0   # extrapolated flow where keyframe 1 does not see keyframe 0's cells
    maps[0, 2][6, 12] = 2.0   # a mover in view
    targets = {(0, 1): fe.grid_coords - torch.tensor([5.0, 0.0]), (0, 2): fe.grid_coords.clone()}
    targets[0, 1][3, 2] = torch.tensor([2.0, 3.0])  # the mover's correspondence stays in view
    for key, d in maps.items():
        weight = torch.ones(H, W, 2)
        fe.cache.put(*key, targets[key], weight)
        fe._raw[key], fe._epipolar[key] = weight, (d, weight)
    fe._mask_movers({0})
    return fe.cache.weight((0, 1))[..., 0].float(), fe.cache.weight((0, 2))[..., 0].float()


def test_with_the_view_rule_a_cell_leaving_one_edge_s_view_loses_only_that_edge():
    far, near = _frontend_with_a_step_aside(in_view=True)
    assert (far[:, :5] == 0).all() and near[:, :5].sum() == near[:, :5].numel() - 1  # unseen on the long edge only
    assert far[6, 12] == 0 and near[6, 12] == 0                  # the movers on both
    assert near[3, 2] == 0                                       # (the one flagged where only its flow stays in view)
    assert far[:, 5:].sum() == far[:, 5:].numel() - 1 and near.sum() == near.numel() - 2
    far, near = _frontend_with_a_step_aside(in_view=False)
    assert (near[:, :5] == 0).all()  # without it: zeroed on every edge
