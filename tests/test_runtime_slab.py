"""Row slabs (runtime/slab.py) and the two stores built on them: the edge cache and the keyframe features."""

from __future__ import annotations

from concurrent.futures import Future

import numpy as np
import pytest
import torch

from droidw_cli.runtime.slab import RowSlab
from droidw_cli.slam import graph
from droidw_cli.slam.keyframes import KeyframeBuffer


def test_slab_reuses_the_lowest_free_row_and_keeps_rows_when_it_grows():
    slab = RowSlab((torch.float32, torch.float16), min_grow=2)
    rows = [slab.store(torch.full((2, 3), float(v)), torch.full((3,), float(-v))) for v in range(3)]
    assert rows == [0, 1, 2] and slab.capacity == 4 and slab.generation == 2 and len(slab) == 3
    slab.release(1)
    slab.release(0)
    assert slab.store(torch.full((2, 3), 7.0), torch.zeros(3)) == 0  # the lowest free row first
    target, weight = slab.rows([2, 0])
    assert target.dtype == torch.float32 and weight.dtype == torch.float16
    assert target[:, 0, 0].tolist() == [2.0, 7.0] and weight[:, 0].tolist() == [-2.0, 0.0]
    assert len(slab) == 2
    with pytest.raises(ValueError, match="shape"):
        slab.store(torch.zeros(3, 2), torch.zeros(3))
    with pytest.raises(ValueError, match="expected 2 values"):
        slab.store(torch.zeros(2, 3))


def test_edge_cache_churn_stays_in_a_bounded_slab_and_edge_sets_are_exact():
    cache = graph.EdgeCache()
    rng = torch.Generator().manual_seed(0)
    stored = {}
    for k in range(1, 400):  # a long video: each keyframe adds its edges, those 30 keyframes back are dropped
        for j in (k - 1, max(0, k - 2)):
            t, w = torch.randn(4, 5, 2, generator=rng), torch.rand(4, 5, 2, generator=rng)
            cache.put(k, j, t, w)
            stored[(k, j)] = (t, w.half().float())
        cache.drop_before(k - 30)
    live = [p for p in stored if min(p) >= 399 - 30]
    assert sorted(cache.pairs()) == sorted(live)
    assert cache._slab.capacity == 256  # 60 live edges at a time: the first block, never grown
    es = cache.edge_set(live, offset=10)
    assert torch.equal(es.target, torch.stack([stored[p][0] for p in live]))
    assert torch.equal(es.weight, torch.stack([stored[p][1] for p in live]))
    assert es.ii.tolist() == [p[0] - 10 for p in live]
    a, b = live[0]
    cache.put(a, b, cache.target((a, b)), cache.weight((a, b)) * 0)  # overwrite in place
    assert float(cache.weight((a, b)).abs().sum()) == 0.0 and len(cache) == len(live)


def _pose():
    return torch.tensor([0, 0, 0, 0, 0, 0, 1.0])


def test_keyframe_features_survive_the_slab_growing_and_archived_rows_are_reused():
    buf = KeyframeBuffer((3, 4), feature_channels=2)
    thumb = np.zeros((1, 1, 3), np.uint8)
    pending = Future()
    for k in range(70):  # past the first 64 rows: the slab moves
        feats = pending if k == 5 else torch.full((2, 3, 4), float(k))
        buf.append(k, float(k), _pose(), 1.0, thumb, features=feats)
    pending.set_result(torch.full((2, 3, 4), 5.0))
    block = buf.feature_block(0, 70, torch.float32)
    assert block[:, 1, 2, 3].tolist() == [float(k) for k in range(70)]
    assert buf.features[5].dtype == torch.float16
    freed = sorted(buf._feature_row[k] for k in [*range(10), 12])
    for k in range(10):
        buf.archive(k, None, torch.zeros(3, 4))
    buf.remove(12)  # keyframe 12's row is free too; the later keyframes move down
    for k in range(11):  # the archived and removed rows are reused first
        buf.append(100 + k, 0.0, _pose(), 1.0, thumb, features=torch.full((2, 3, 4), 100.0 + k))
    assert sorted(buf._feature_row[-11:]) == freed and buf._feature_slab.capacity == 128
    block = buf.feature_block(10, len(buf), torch.float32, channels_last=True)
    expect = [float(k) for k in range(10, 70) if k != 12] + [100.0 + k for k in range(11)]
    assert block[:, 0, 0, 0].tolist() == expect
