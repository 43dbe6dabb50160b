"""track_objects' flow carry: the previous keyframe's objects moved by the recorded edge flow."""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics.inloop import KeyframeMasks
from droidw_cli.dynamics.objects import _carry


def _masks(h: int, w: int, edges: dict) -> KeyframeMasks:
    km = KeyframeMasks(DynamicsConfig(), (h, w), consistency=False, keep_flow=True)
    for _ in range(3):
        km.append(np.zeros((h * 8, w * 8, 3), np.uint8))
    km.edges.update(edges)
    return km


def _edge(h: int, w: int, dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    target = np.stack([gx + dx, gy + dy], -1).astype(np.float16)
    return target, np.full((h, w), 255, np.uint8)


def test_objects_move_with_the_flow_and_leave_the_image():
    h, w = 20, 30
    prev = np.full((h, w), -1, np.int16)
    prev[5:10, 4:9] = 3
    prev[12:16, 24:29] = 7
    masks = _masks(h, w, {(0, 1): _edge(h, w, 3.2, -1.0)})
    got = _carry(masks, 1, prev)
    want = np.zeros((h, w), bool)
    want[4:9, 7:12] = True
    assert set(got) == {3, 7}
    assert np.array_equal(got[3], want)
    assert got[7].sum() == 4 * 3  # the part moved past the right border is dropped
    assert _carry(masks, 2, prev) == {}  # no edge (1, 2) recorded
    assert _carry(masks, 1, np.full((h, w), -1, np.int16)) == {}


def test_with_the_backward_edge_each_pixel_takes_the_id_at_its_match():
    """Square 3 moves right by 4 over square 7 that stays: the pixels whose match lies on 3 are 3's."""
    h, w = 20, 30
    prev = np.full((h, w), -1, np.int16)
    prev[5:10, 14:19] = 7
    prev[5:10, 4:9] = 3
    back_t, conf = _edge(h, w, 0.0, 0.0)
    back_t = back_t.astype(np.float32)
    back_t[5:10, 8:13, 0] -= 4  # the occluder's pixels in k come from 4 px to the left
    masks = _masks(h, w, {(1, 0): (back_t.astype(np.float16), conf), (0, 1): _edge(h, w, 50.0, 0.0)})
    got = _carry(masks, 1, prev)
    want3 = np.zeros((h, w), bool)
    want3[5:10, 4:13] = True  # its old place too: there the (identity) flow points at it
    assert np.array_equal(got[3], want3)  # the backward edge wins over the forward one
    assert got[7].sum() == 5 * 5


def test_the_carry_survives_archiving():
    """Settled keyframes drop their flow (finalise) but keep where each pixel lands: the same carry."""
    h, w = 20, 30
    prev = np.full((h, w), -1, np.int16)
    prev[5:10, 4:9] = 3
    masks = _masks(h, w, {(1, 0): _edge(h, w, -2.0, 1.0), (0, 1): _edge(h, w, 2.0, -1.0), (2, 1): _edge(h, w, 0, 0)})
    before = _carry(masks, 1, prev)
    poses = torch.tensor([[0, 0, 0, 0, 0, 0, 1.0]] * 3)
    masks.finalise(2, poses, torch.ones(3, h, w), torch.tensor([20.0, 20.0, w / 2, h / 2]))
    assert set(masks.edges) == {(2, 1)} and set(masks.matches) == {(0, 1), (1, 0)}
    after = _carry(masks, 1, prev)
    assert set(after) == set(before) == {3}
    assert np.array_equal(after[3], before[3]) and after[3].sum() == 25
