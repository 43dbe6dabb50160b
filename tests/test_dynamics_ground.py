"""The ground cue of track_objects: places on the floor (2D), given to the tracker only with sensor depth."""

from __future__ import annotations

import numpy as np
import pytest
import torch

import droidw_cli.dynamics.objects as objects
from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics.inloop import KeyframeMasks
from droidw_cli.dynamics.objects import _on_ground, _up


def _rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_up_is_the_mean_of_the_upright_cameras_minus_y_and_ground_drops_it():
    c2w = np.tile(np.eye(4), (4, 1, 1))
    for i, (yaw, pitch) in enumerate([(0.0, 0.1), (0.8, -0.1), (-1.5, 0.0), (2.5, 0.0)]):
        c2w[i, :3, :3] = _rot_y(yaw) @ _rot_x(pitch)  # panning and tilting, no roll: the world's up is −y
    up = _up(c2w)
    assert np.allclose(up, [0.0, -1.0, 0.0], atol=0.02)  # tilts of ±0.1 rad, not all cancelling
    points = np.array([[1.0, -1.7, 3.0], [1.0, 0.0, 3.0], [-2.0, 0.5, 1.0]])
    flat = _on_ground(points, up)
    assert flat.shape == (3, 2)
    assert abs(np.linalg.norm(flat[1] - flat[2]) - np.hypot(3.0, 2.0)) < 0.02  # the distance across the floor
    assert np.linalg.norm(flat[0] - flat[1]) < 0.05  # a head above its feet: the same place on the floor
    assert np.linalg.norm(flat[0] - flat[2]) > 3.0


def _rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_no_up_when_the_cameras_are_not_held_upright():
    c2w = np.tile(np.eye(4), (4, 1, 1))
    for i, roll in enumerate([0.0, np.pi / 2, np.pi, 3 * np.pi / 2]):  # the camera turned round its axis
        c2w[i, :3, :3] = _rot_z(roll)
    assert _up(c2w) is None
    assert _up(c2w[:0]) is None
    c2w[:, :3, :3] = _rot_z(0.3)  # one steady roll of 17°: still a floor (tilted)
    assert _up(c2w) is not None


@pytest.mark.parametrize("sensor_depth", [True, False])
def test_track_objects_gives_the_ground_cue_only_with_sensor_depth(monkeypatch, sensor_depth):
    h, w, n = 12, 16, 3
    km = KeyframeMasks(DynamicsConfig(), (h, w), consistency=False)
    for _ in range(n):
        km.append(np.zeros((h * 8, w * 8, 3), np.uint8))
    box = torch.zeros(h, w, dtype=torch.bool)
    box[3:9, 5:10] = True
    poses = torch.tensor([[0.0, 0, 0, 0, 0, 0, 1]]).repeat(n, 1)
    disps = torch.full((n, h, w), 0.5)  # 2 m
    seen = []
    update = objects.DynamicObjectTracker.update

    def spy(self, mask, *args, **kwargs):
        seen.append((args[5] if len(args) > 5 else kwargs.get("ground"),
                     args[6] if len(args) > 6 else kwargs.get("predicted_ground")))
        return update(self, mask, *args, **kwargs)

    monkeypatch.setattr(objects.DynamicObjectTracker, "update", spy)
    kk = torch.tensor([10.0, 10.0, w / 2, h / 2])
    rec = objects.track_objects(km, poses, disps, kk, DynamicsConfig(), [box.clone() for _ in range(n)],
                                sensor_depth=sensor_depth)
    assert len(seen) == n and len(np.unique(rec.ids[rec.ids >= 0])) == 1
    if not sensor_depth:
        assert all(g is None and p is None for g, p in seen)
        return
    ground, _ = seen[0]
    assert ground.shape == (h, w, 2) and np.isfinite(ground).all()
    # identity cameras, everything 2 m away: up is −y, so the floor distance of two pixels is their x distance
    x = (np.arange(w) - w / 2) / 10 * 2
    assert np.allclose(np.linalg.norm(ground[0] - ground[0, :1], axis=1), np.abs(x - x[0]))
    assert np.allclose(ground[:, 3], ground[0, 3])  # a column of pixels: one place on the floor
    _, predicted = seen[2]  # by the third keyframe the object has a centroid and a (zero) velocity
    (g,) = predicted.values()
    assert np.allclose(g, ground[box.numpy()].mean(0), atol=1e-9)
