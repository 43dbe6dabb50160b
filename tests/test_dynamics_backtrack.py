"""Backtracking new object tracks through the keyframes before their birth (dynamics/backtrack.py)."""

import numpy as np

from droidw_cli.dynamics.backtrack import backtrack, carry_back

H, W = 24, 40


def box(x: int, y: int = 8, w: int = 4, h: int = 8) -> np.ndarray:
    m = np.zeros((H, W), bool)
    m[y:y + h, x:x + w] = True
    return m


def test_carry_back_moves_at_the_image_velocity_scaled_by_time():
    times = np.array([0.0, 0.2, 0.3])  # j → j+1 twice as long as j+1 → j+2
    nxt, nxt2 = box(12), box(14)  # moving right by 2 px per 0.1 s: 4 px further left 0.2 s before
    moved = carry_back(times, 0, nxt, nxt2)
    assert np.array_equal(moved, box(8))
    assert carry_back(times, 0, nxt, None) is None


def test_a_walker_split_off_a_blob_gets_its_id_back_before_the_split():
    """Walker A stands still at x=4; walker B walks right 3 px a keyframe and touches A in keyframes 0-2, so
    the forward tracker gave the blob A's id 0; from keyframe 3 B is apart, as id 1."""
    n = 7
    a = [box(4) for _ in range(n)]
    b = [box(8 + 3 * k) for k in range(n)]
    ids = np.full((n, H, W), -1, np.int16)
    dynamic = np.zeros((n, H, W), bool)
    for k in range(n):
        dynamic[k] = a[k] | b[k]
        ids[k][a[k]] = 0
        ids[k][b[k]] = 0 if k < 3 else 1
    out = backtrack(ids, dynamic, np.arange(n, dtype=float))
    for k in range(n):
        assert (out[k][b[k]] == 1).all(), k
        assert (out[k][a[k]] == 0).all(), k
    assert (ids[0][b[0]] == 0).all()  # the input is not changed


def test_an_id_lost_at_a_merge_is_renamed_to_the_one_after_it():
    """One walker: id 0 in keyframes 0-2, id 2 from keyframe 3 on; both are one track."""
    n = 6
    walker = [box(2 + 3 * k) for k in range(n)]
    ids = np.full((n, H, W), -1, np.int16)
    dynamic = np.zeros((n, H, W), bool)
    for k in range(n):
        dynamic[k] = walker[k]
        ids[k][walker[k]] = 0 if k < 3 else 2
    out = backtrack(ids, dynamic, np.arange(n, dtype=float))
    assert all((out[k][walker[k]] == 2).all() for k in range(n))
    assert not (out == 0).any()


def test_no_backtracking_where_nothing_moved_or_for_a_short_lived_blob():
    n = 6
    walker = [box(2 + 3 * k) for k in range(n)]
    ids = np.full((n, H, W), -1, np.int16)
    dynamic = np.zeros((n, H, W), bool)
    for k in range(3, n):  # a walker first seen in keyframe 3, nothing dynamic before
        dynamic[k] = walker[k]
        ids[k][walker[k]] = 5
    assert np.array_equal(backtrack(ids, dynamic, np.arange(n, dtype=float)), ids)
    # a blob that lives two keyframes (min_life 3) is not carried back into the blob it split from
    ids2 = np.full((n, H, W), -1, np.int16)
    for k in range(n):
        dynamic[k] = walker[k]
        ids2[k][walker[k]] = 1 if k in (3, 4) else 0
    assert np.array_equal(backtrack(ids2, dynamic, np.arange(n, dtype=float)), ids2)
