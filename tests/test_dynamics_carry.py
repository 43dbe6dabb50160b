"""track_objects' flow carry: the previous keyframe's objects moved by the recorded edge flow."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from droidw_cli.dynamics.objects import _carry


def _edge(h: int, w: int, dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    target = np.stack([gx + dx, gy + dy], -1).astype(np.float16)
    return target, np.full((h, w), 255, np.uint8)


def test_objects_move_with_the_flow_and_leave_the_image():
    h, w = 20, 30
    prev = np.full((h, w), -1, np.int16)
    prev[5:10, 4:9] = 3
    prev[12:16, 24:29] = 7
    masks = SimpleNamespace(edges={(0, 1): _edge(h, w, 3.2, -1.0)})
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
    masks = SimpleNamespace(edges={(1, 0): (back_t.astype(np.float16), conf), (0, 1): _edge(h, w, 50.0, 0.0)})
    got = _carry(masks, 1, prev)
    want3 = np.zeros((h, w), bool)
    want3[5:10, 4:13] = True  # its old place too: there the (identity) flow points at it
    assert np.array_equal(got[3], want3)  # the backward edge wins over the forward one
    assert got[7].sum() == 5 * 5
