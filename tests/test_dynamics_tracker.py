"""DynamicObjectTracker: ids across frames and the three track-ending rules."""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.dynamics import DynamicObjectTracker

H, W = 60, 100


def _box(x0: int, y0: int, sw: int, sh: int) -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[y0:y0 + sh, x0:x0 + sw] = True
    return m


def test_id_is_kept_while_object_moves():
    tr = DynamicObjectTracker()
    ids = []
    for k in range(6):
        objs = tr.update(_box(20 + 4 * k, 20, 12, 12))
        assert len(objs) == 1
        ids.append(objs[0].id)
        assert objs[0].area == 144 and objs[0].mask.sum() == 144
    assert ids == [0] * 6 and tr.ended == []
    assert abs(objs[0].centre[0] - (20 + 20 + 5.5)) <= 0.5  # inscribed-circle centre of the last box


def test_two_objects_keep_their_own_ids():
    tr = DynamicObjectTracker()
    first = tr.update(_box(10, 10, 10, 10) | _box(60, 30, 14, 14))
    side = {o.centre[0] < W / 2: o.id for o in first}
    assert len(side) == 2
    second = tr.update(torch.as_tensor(_box(13, 11, 10, 10) | _box(57, 31, 14, 14)))
    assert len(second) == 2
    for o in second:
        assert o.id == side[o.centre[0] < W / 2]


def test_area_jump_ends_track_and_starts_a_new_one():
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(30, 20, 10, 10))
    (b,) = tr.update(_box(31, 20, 10, 14))  # 1.4× — still the same track
    assert b.id == a.id
    (c,) = tr.update(_box(31, 18, 14, 18))  # 252 / 140 = 1.8×
    assert c.id != a.id
    assert [(e.id, e.reason) for e in tr.ended] == [(a.id, "growth")]


def test_border_ends_track():
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(20, 25, 8, 8))
    (b,) = tr.update(_box(8, 25, 8, 8))
    assert b.id == a.id
    assert tr.update(_box(0, 25, 6, 8)) == []  # centre x = 2.5 < 4 % of 100
    assert [(e.id, e.reason) for e in tr.ended] == [(a.id, "border")]
    assert tr.update(_box(0, 25, 6, 8)) == []  # objects at the border start no tracks


def test_lost_object_ends_track():
    tr = DynamicObjectTracker()
    (a,) = tr.update(_box(10, 20, 10, 10))
    (b,) = tr.update(_box(40, 20, 10, 10))  # centre moves 30 px > 20 % of 100 and is not inside: no match
    assert b.id != a.id and [(e.id, e.reason) for e in tr.ended] == [(a.id, "lost")]
    assert tr.update(np.zeros((H, W), bool)) == [] and tr.ended[-1].reason == "lost"


def test_centre_jump_ends_track():
    tr = DynamicObjectTracker(max_growth=100.0)
    (d,) = tr.update(_box(10, 10, 60, 5) | _box(10, 10, 5, 40))  # an L: its centre sits at its left end
    # the old centre is still inside the new blob, but the blob's centre is now in the wide right leg (> 20 px away)
    (e,) = tr.update(_box(10, 10, 60, 5) | _box(62, 10, 8, 40))
    assert e.id != d.id and [(x.id, x.reason) for x in tr.ended] == [(d.id, "jump")]
