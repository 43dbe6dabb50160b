"""What keeps a long run's memory flat: chunked end-of-run maps and compact per-keyframe storage."""

from __future__ import annotations

import numpy as np
import pypose as pp
import pytest
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.slam import keyframe_maps
from droidw_cli.slam.frontend import Frontend

GRID = (6, 8)
K8 = torch.tensor([8.0, 8.0, 4.0, 3.0])


def _frontend_with_features(n: int, channels: int = 4) -> Frontend:
    """n keyframes along x with random features, neighbour and skip edges (noisy targets), and a random θ."""
    cfg = load_config("default", [])
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), None, GRID, K8, channels)
    g = torch.Generator().manual_seed(3)
    h, w = GRID
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32), indexing="ij")
    grid = torch.stack([xs, ys], -1)
    for k in range(n):
        w2c = pp.SE3(torch.tensor([-0.05 * k, 0, 0, 0, 0, 0, 1.0])).tensor().float()
        fe.buffer.append(k, k / 10.0, w2c, 0.5, np.zeros((2, 2, 3), np.uint8),
                         features=torch.randn(channels, h, w, generator=g))
        for j in (k - 1, k - 2):
            if j >= 0:
                for a, b in ((k, j), (j, k)):
                    fe.cache.put(a, b, grid + 0.3 * torch.randn(h, w, 2, generator=g),
                                 torch.rand(h, w, 2, generator=g))
    fe.shared.theta = 0.5 * torch.randn(fe.shared.theta.shape[0], generator=g)
    fe.initialised = True
    return fe


@pytest.mark.parametrize("chunk", [1, 7])
def test_uncertainty_with_chunked_evidence_equals_one_block(monkeypatch, chunk):
    fe = _frontend_with_features(23)
    fe.archive(0, 4)  # the oldest are frozen (float16), the live ones follow
    assert fe.evidence(4, 6) is not None  # the default config reads evidence maps
    monkeypatch.setattr(keyframe_maps, "UNCERTAINTY_CHUNK", 10**6)
    whole = fe.uncertainty()
    monkeypatch.setattr(keyframe_maps, "UNCERTAINTY_CHUNK", chunk)
    assert torch.equal(fe.uncertainty(), whole)
    assert torch.equal(fe.uncertainty(5, 17), whole[5:17])


def test_feature_block_converts_without_changing_values():
    fe = _frontend_with_features(5)
    block = fe.buffer.feature_block(1, 4, torch.float32)
    assert block.dtype == torch.float32 and torch.equal(block, fe.buffer.feature_block(1, 4).float())


def test_channels_last_blocks_reuse_the_last_windows_rows_and_keep_their_values(monkeypatch):
    """feature_block keeps a window's float32 channels-last rows for the next window (keyframes/ROWS_CACHED)."""
    import droidw_cli.slam.keyframes as keyframes_mod

    fe = _frontend_with_features(9)
    buf = fe.buffer

    def reference(lo, hi):  # the stored features, converted and laid out channels-last afresh
        return torch.stack([f.float() for f in buf.features[lo:hi]]).contiguous(memory_format=torch.channels_last)

    first = buf.feature_block(1, 5, torch.float32, channels_last=True)
    assert first.is_contiguous(memory_format=torch.channels_last) and torch.equal(first, reference(1, 5))
    assert buf.feature_block(1, 5, torch.float32, channels_last=True) is first  # the same keyframes: the same block
    moved = buf.feature_block(2, 7, torch.float32, channels_last=True)  # the next window: rows 2-4 from the cache
    assert moved is not first and torch.equal(moved, reference(2, 7))
    buf.remove(4)  # keyframe removal renumbers: the cache follows the features, not their index
    assert torch.equal(buf.feature_block(2, 7, torch.float32, channels_last=True), reference(2, 7))
    monkeypatch.setattr(keyframes_mod, "ROWS_CACHED", 3)
    big = buf.feature_block(0, 8, torch.float32, channels_last=True)  # a global BA's block: not kept
    assert torch.equal(big, reference(0, 8)) and buf.feature_block(0, 8, torch.float32, channels_last=True) is not big


def test_thumbnails_stay_encoded_and_decode_to_the_same_images():
    from droidw_cli.slam.keyframes import KeyframeBuffer

    buf = KeyframeBuffer(GRID, capacity=2)
    assert np.asarray(buf.thumbnail_stack()).shape == (0, 1, 1, 3)
    ramp = np.add.outer(np.arange(12) * 8, np.arange(16) * 6)
    thumbs = [np.stack([ramp + 10 * k, ramp[::-1] + 5, 200 - ramp], -1).astype(np.uint8) for k in range(4)]
    for k, t in enumerate(thumbs):
        buf.append(k, k / 30.0, torch.tensor([0, 0, 0, 0, 0, 0, 1.0]), 1.0, t)
    stack = buf.thumbnail_stack()
    assert stack.shape == (4, 12, 16, 3) and len(stack) == 4 and stack.dtype == np.uint8
    every = np.asarray(stack)
    assert every.shape == stack.shape and every.dtype == np.uint8
    for k in range(4):
        assert np.array_equal(every[k], buf.thumbnail(k)) and np.array_equal(stack[k], every[k])
        assert np.abs(every[k].astype(int) - thumbs[k]).mean() < 3  # JPEG, quality 95
    assert np.array_equal(stack[1:3], every[1:3])


def test_keyframe_arrays_keep_the_stored_dtypes():
    """The result holds float16 confidence, int16 ids and encoded thumbnails; keyframes.npz is unchanged."""
    from types import SimpleNamespace

    from droidw_cli.export.run_files import keyframe_arrays
    from droidw_cli.io.jpeg import JpegStack, encode_rgb

    k, (h, w) = 3, GRID
    image = np.full((4, 4, 3), 100, np.uint8)
    result = SimpleNamespace(
        kf_index=np.arange(k), kf_timestamps=np.arange(k, dtype=np.float64), kf_poses_c2w=np.zeros((k, 4, 4)),
        kf_disps=np.ones((k, h, w), np.float32), intrinsics_work=np.ones(4), work_size=(48, 64),
        kf_images=JpegStack([encode_rgb(image, 95)] * k, image.shape),
        kf_confidence=np.full((k, h, w), 0.5, np.float16), kf_dynamic=np.zeros((k, h, w), bool),
        kf_object_ids=np.full((k, h, w), -1, np.int16), objects=np.zeros((0, 8)),
        kf_uncertainty=np.ones((k, h, w), np.float32), kf_features=None, theta=None)
    arrays = keyframe_arrays(result)
    assert arrays["images"].shape == (k, 4, 4, 3) and arrays["images"].dtype == np.uint8
    assert arrays["confidence"].dtype == np.float16 and arrays["object_ids"].dtype == np.int32
    assert arrays["disps"].dtype == np.float32 and arrays["uncertainty"].dtype == np.float32
    assert arrays["dynamic"].dtype == bool and int(arrays["object_ids"].min()) == -1


def test_anchor_table_returns_what_was_put_across_growth():
    from droidw_cli.slam.filler import AnchorTable, _Anchored

    g = torch.Generator().manual_seed(1)
    table, put = AnchorTable(), {}
    for f in range(2500):  # past two growth steps
        rec = (_Anchored(f // 9, torch.randn(7, generator=g)) if f % 5 == 0 else
               _Anchored(f // 9, torch.randn(7, generator=g), f // 9 + 9, torch.randn(7, generator=g), f / 2500))
        table[f * 3] = put[f * 3] = rec
    table[3] = put[3] = _Anchored(7, torch.ones(7))  # an overwrite keeps its row
    assert len(table) == 2500 and 3 in table and 4 not in table and table.get(4) is None
    assert list(table) == list(put)
    for f, rec in put.items():
        got = table.get(f)
        assert (got.a, got.b, got.alpha) == (rec.a, rec.b, rec.alpha)
        assert torch.equal(got.rel_a, rec.rel_a)
        assert (got.rel_b is None) == (rec.rel_b is None) and (rec.rel_b is None or torch.equal(got.rel_b, rec.rel_b))


def test_packed_masks_behave_like_a_list_of_bool_tensors():
    from droidw_cli.dynamics.inloop import PackedMasks

    g = torch.Generator().manual_seed(2)
    masks = PackedMasks((5, 7))  # 35 pixels: not a multiple of 8
    ref = [torch.rand(5, 7, generator=g) > 0.5 for _ in range(4)]
    for m in ref:
        masks.append(m)
    other = torch.rand(5, 7, generator=g) > 0.7
    masks[2] |= other
    ref[2] = ref[2] | other
    masks[0] = np.zeros((5, 7), bool)
    ref[0] = torch.zeros(5, 7, dtype=torch.bool)
    del masks[1], ref[1]
    assert len(masks) == 3
    assert all(torch.equal(a, b) and a.dtype == torch.bool for a, b in zip(masks, ref))
    assert np.array_equal(masks.stacked(), torch.stack(ref).numpy())
    assert PackedMasks((5, 7)).stacked().shape == (0, 5, 7)
    with pytest.raises(ValueError):
        masks.append(torch.zeros(7, 5, dtype=torch.bool))


def test_channels_last_features_are_what_the_cpu_feature_table_builds():
    """The CPU backend gets float32 channels-last features: the same table as from the float16 stack, no copy."""
    from droidw_backend_cpu.uncertainty import FeatureTable

    from droidw_cli.slam.optimizer import window_state

    fe = _frontend_with_features(6)
    assert fe.backend.feature_layout == "float32_channels_last"
    st = window_state(fe.buffer, 1, 5, fe.shared, True, "float32_channels_last")
    stored = window_state(fe.buffer, 1, 5, fe.shared, True)
    assert stored.features.dtype == torch.float16 and st.features.dtype == torch.float32
    assert st.features.is_contiguous(memory_format=torch.channels_last)
    table = FeatureTable()
    cl, norms = table.get(st.features)
    assert cl is st.features  # used as it is
    ref_cl, ref_norms = FeatureTable().get(stored.features)
    assert torch.equal(cl, ref_cl) and torch.equal(norms, ref_norms)
    theta = torch.tensor([*fe.shared.theta[:4].tolist(), 0.3])  # θ[:C] and the bias, no map inputs
    assert torch.equal(table.logits(cl, theta), FeatureTable().logits(stored.features, theta))
    with pytest.raises(ValueError, match="layout"):
        window_state(fe.buffer, 1, 5, fe.shared, True, "bogus")
