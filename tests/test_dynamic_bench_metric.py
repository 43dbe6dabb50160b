"""benchmarks/dynamic_bench.py: the id-switch metrics (issue 11: "at most one id switch per object
per sequence while it stays in view")."""

from __future__ import annotations

import numpy as np
from bench_scripts import load

bench = load("dynamic_bench")

H, W = 20, 20  # 400 cells: "in view" is at least 2 cells (0.5 %)


def _walker(cells_per_frame: list[int]) -> np.ndarray:
    """(K, H, W) masks covering the given number of cells (a row from the top-left)."""
    out = np.zeros((len(cells_per_frame), H, W), bool)
    for k, n in enumerate(cells_per_frame):
        out[k].reshape(-1)[:n] = True
    return out


def test_switches_count_only_while_the_walker_stays_in_view():
    inst = _walker([30, 30, 30, 0, 30, 30])[None]  # visible, gone for a keyframe, back
    ids = np.full(inst.shape[1:], -1, np.int32)
    for k, i in enumerate([0, 0, 1, -1, 2, 2]):
        ids[k][inst[0, k]] = i
    assert bench.id_switches_any(inst, ids) == 2  # 0→1 and 1→2
    assert bench.id_switches(inst, ids) == 1  # 1→2 came after it left the view


def test_a_walker_covering_a_cell_is_out_of_view_and_keyframes_without_an_id_are_skipped():
    inst = _walker([30, 1, 30, 30, 30])[None]  # one cell: out of view
    ids = np.full(inst.shape[1:], -1, np.int32)
    for k, i in enumerate([0, 5, 1, -1, 1]):
        ids[k][inst[0, k]] = i
    assert bench.id_switches(inst, ids) == 0  # 0 | (out of view) | 1, no id, 1
    assert bench.id_switches_any(inst, ids) == 2  # 0→5→1


def test_the_worst_walker_counts_and_the_majority_id_is_the_walkers():
    a = _walker([30, 30, 30, 30])
    b = np.zeros_like(a)
    b[:, 10:, :] = True
    ids = np.full(a.shape, -1, np.int32)
    ids[a] = 7
    ids[:, 10:, :] = 3
    ids[2, 10:, :3] = 9  # a few of b's pixels with another id: the majority is still 3
    ids[1][a[1]] = 8
    assert bench.id_switches(np.stack([a, b]), ids) == 2  # a: 7→8→7; b: none


def test_shared_ids_count_the_walkers_whose_id_another_walker_in_view_has():
    a = _walker([30, 30, 30, 30])
    b = np.zeros_like(a)
    b[:, 10:, :] = True
    b[3] = False  # b out of view in the last keyframe
    ids = np.full(a.shape, -1, np.int32)
    ids[a] = 1
    ids[b] = 2
    ids[:2][b[:2]] = 1  # one id on both for two keyframes
    # pairs with an id: a × 4, b × 3; shared: a and b in keyframes 0 and 1
    assert abs(bench.id_shared(np.stack([a, b]), ids) - 4 / 7) < 1e-9
    ids[:2][b[:2]] = 2
    assert bench.id_shared(np.stack([a, b]), ids) == 0.0


def test_mots_switches_leave_a_walker_hidden_in_a_pile_unmatched_but_count_a_swap():
    a = np.zeros((5, H, W), bool)
    b = np.zeros_like(a)
    a[:, :, :8] = True  # 160 cells
    b[:, :, 16:] = True  # 80 cells: the pile's IoU is 160 / 240 with a, 80 / 240 with b
    ids = np.full(a.shape, -1, np.int32)
    ids[a] = 1
    ids[b] = 2
    ids[2][b[2]] = 1  # keyframe 2: one id on both walkers (a pile)
    walkers = np.stack([a, b])
    assert bench.id_switches(walkers, ids) == 2  # b: 2 → 1 → 2 by the majority id
    assert bench.mots_id_switches(walkers, ids) == (0, 0.9)  # b unmatched in the pile: 9 of 10 pairs matched
    ids[3:][a[3:]], ids[3:][b[3:]] = 2, 1  # the walkers trade ids from keyframe 3 on
    assert bench.mots_id_switches(walkers, ids)[0] == 1


def test_mots_switches_need_an_overlap_above_the_iou_and_restart_after_the_walker_leaves_the_view():
    a = _walker([40, 40, 0, 40])[None]
    ids = np.full(a.shape[1:], -1, np.int32)
    ids[0][a[0, 0]] = 3
    ids[1].reshape(-1)[:200] = 4  # covers the walker, IoU 40 / 200: not matched
    ids[3][a[0, 3]] = 5  # back after leaving the view: a new visit
    assert bench.mots_id_switches(a, ids) == (0, 2 / 3)
    assert bench.mots_id_switches(a, ids, iou=0.1) == (1, 1.0)  # 3 → 4 once IoU 0.2 counts
