"""The cells of a keyframe that another keyframe sees under the current poses and disparities."""

from __future__ import annotations

import types

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
