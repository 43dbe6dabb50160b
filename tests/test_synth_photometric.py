"""Synthetic photometric realism: motion blur, gain drift, flicker, noise, JPEG — and unchanged old presets."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from droidw_cli.synth import SynthConfig, build_scene
from droidw_cli.synth.exposure import sample_count, sample_offsets
from droidw_cli.synth.photometric import to_display, to_linear

SMALL = {"width": 160, "height": 120}


def _digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


@pytest.mark.parametrize("preset, overrides, k, rgb, geometry, pose", [
    ("dynamic-small", {"seed": 1}, 17, "a12fa5ecc7907dca", "d53527af7eb76ded", "9694eae2e115acd9"),
    ("static", {"seed": 0, **SMALL}, 150, "826b3540e63ccd23", "507e477ae9b465d6", "efef74f9535355f6"),
    ("dynamic", {"seed": 2, **SMALL}, 299, "0cd2d7c0b5b05804", "2a5b6edf02cbcaaf", "f66c70446266ae6a"),
    ("busy-small", {"seed": 3, "noise_std": 2.0, **SMALL}, 20, "7c52bd94f1e3796e", "54629c3a827b4079",
     "2a6e73867a5f7363"),
])
def test_old_presets_render_the_same_bytes(preset, overrides, k, rgb, geometry, pose):
    # checksums computed once at the commit before camera motions and photometric options existed
    # (pinned on the development machine: float rounding of another CPU or numpy could change them)
    f = build_scene(SynthConfig.preset(preset, **overrides)).frame(k)
    assert (_digest(f.rgb), _digest(f.depth, f.mask), _digest(f.pose_c2w)) == (rgb, geometry, pose)


def test_options_are_off_by_default():
    cfg = SynthConfig()
    assert (cfg.motion, cfg.blur, cfg.jpeg_quality, cfg.gain_drift, cfg.flicker, cfg.noise_std) == (
        "handheld", 0.0, 0, 0.0, 0.0, 0.0)
    sc = build_scene(SynthConfig(frames=20, **SMALL))
    assert sc.photometric.gain(7) == 1.0
    assert len(sc.exposure_samples(7)) == 1


def test_srgb_tables_round_trip():
    grey = np.arange(256, dtype=np.uint8).reshape(16, 16, 1).repeat(3, 2)
    assert np.array_equal(np.rint(to_display(to_linear(grey))).astype(np.uint8), grey)
    lin = to_linear(grey)
    assert lin.dtype == np.float32 and lin[0, 0, 0] == 0.0 and lin[-1, -1, 0] == 1.0
    assert np.all(np.diff(lin[..., 0].ravel()) > 0)
    assert to_display(np.float32([[2.0, -1.0]])).tolist() == [[255.0, 0.0]]  # saturates


def test_exposure_samples_follow_the_motion():
    assert sample_count(0.0, 7) == 3 and sample_count(8.9, 7) == 3 and sample_count(9.1, 7) == 5
    assert sample_count(100.0, 7) == 7 and sample_count(100.0, 1) == 1
    off = sample_offsets(0.5, 5)
    np.testing.assert_allclose(off, [-0.2, -0.1, 0.0, 0.1, 0.2])
    assert off[2] == 0.0  # the frame's own render is one of the samples
    still = build_scene(SynthConfig(motion="fixed", static=True, movers=0, blur=0.5, frames=20, **SMALL))
    assert len(still.exposure_samples(5)) == 3
    # a fast turn smears more pixels at a higher resolution and a longer exposure: more samples
    fast = SynthConfig(motion="rotate", static=True, movers=0, blur=0.5, frames=90, seed=2, width=320, height=240)
    counts = {}
    for cfg in (fast, fast.replace(blur=1.0), fast.replace(blur=1.0, blur_samples=5)):
        sc = build_scene(cfg)
        counts[cfg.blur, cfg.blur_samples] = max(len(sc.exposure_samples(k)) for k in range(0, 90, 10))
    assert counts == {(0.5, 7): 3, (1.0, 7): 7, (1.0, 5): 5}


@pytest.fixture(scope="module")
def fixed_walkers():
    base = SynthConfig(motion="fixed", movers=2, frames=60, seed=4, **SMALL)
    return build_scene(base), build_scene(base.replace(blur=0.8))


def test_blur_leaves_a_still_scene_unchanged():
    base = SynthConfig(motion="fixed", static=True, movers=0, frames=20, seed=1, **SMALL)
    sharp, blurred = build_scene(base).frame(6), build_scene(base.replace(blur=0.6)).frame(6)
    assert np.abs(sharp.rgb.astype(int) - blurred.rgb).max() <= 1  # 3 identical sub-frames averaged


def test_blur_smears_the_walkers_only(fixed_walkers):
    sharp, blurred = fixed_walkers
    changed = 0
    for k in (20, 30, 40):
        a, b = sharp.frame(k), blurred.frame(k)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.mask, b.mask)
        np.testing.assert_array_equal(a.pose_c2w, b.pose_c2w)
        # pixels no walker covers at any sub-frame time are static: unchanged up to rounding
        swept = np.zeros_like(a.mask)
        times = blurred.exposure_samples(k)
        assert len(times) >= 3 and times[len(times) // 2] == k
        for s in times:
            swept |= blurred.caster.cast(blurred.boxes(s, static=False), blurred.pose(s)).dynamic
        diff = np.abs(a.rgb.astype(int) - b.rgb).max(-1)
        assert diff[~swept].max() <= 1
        changed += int((diff[swept] > 10).sum())
    assert changed > 50


def test_blur_smooths_a_moving_camera():
    base = SynthConfig(motion="rotate", static=True, movers=0, frames=60, seed=0, **SMALL)
    sharp, blurred = build_scene(base), build_scene(base.replace(blur=0.8))
    for k in (15, 45):
        a, b = sharp.frame(k).rgb.astype(float), blurred.frame(k).rgb.astype(float)
        grad = [np.abs(np.diff(x.mean(-1), axis=1)).mean() for x in (a, b)]
        assert grad[1] < 0.9 * grad[0]
        assert 1.0 < np.abs(a - b).mean() < 30.0


def test_gain_drift_scales_linear_intensity():
    base = SynthConfig(frames=300, seed=2, **SMALL)
    plain, drift = build_scene(base), build_scene(base.replace(gain_drift=0.15))
    gains = np.array([drift.photometric.gain(k) for k in range(300)])
    assert np.all((gains >= 0.85) & (gains <= 1.15)) and np.ptp(gains) > 0.1
    assert np.abs(np.diff(gains)).max() < 0.01  # slow
    for k in (0, 150, 299):
        a, b = to_linear(plain.frame(k).rgb), to_linear(drift.frame(k).rgb)
        unsaturated = (b < 0.95) & (a < 0.95) & (a > 0.02)
        ratio = b[unsaturated].sum() / a[unsaturated].sum()
        assert ratio == pytest.approx(gains[k], abs=0.003)
        np.testing.assert_array_equal(plain.frame(k).depth, drift.frame(k).depth)
    flicker = build_scene(base.replace(flicker=0.02))
    jumps = np.diff([flicker.photometric.gain(k) for k in range(100)])
    assert 0.005 < np.abs(jumps).mean() < 0.06


def test_photometric_options_are_deterministic_and_leave_ground_truth_alone():
    base = SynthConfig.preset("dynamic-small", seed=6, frames=12, **SMALL)
    real = base.replace(blur=0.5, jpeg_quality=70, gain_drift=0.1, flicker=0.01, noise_std=2.0)
    plain, a, b = build_scene(base), build_scene(real), build_scene(real)
    for k in (3, 9):
        fp, fa, fb = plain.frame(k), a.frame(k), b.frame(k)
        assert fa.rgb.tobytes() == fb.rgb.tobytes()  # same config, same bytes
        assert np.array_equal(fa.depth, fp.depth) and np.array_equal(fa.mask, fp.mask)
        assert np.array_equal(fa.pose_c2w, fp.pose_c2w)
        assert 1.0 < np.abs(fa.rgb.astype(float) - fp.rgb).mean() < 20.0
    other = build_scene(real.replace(seed=7)).frame(3).rgb
    assert not np.array_equal(other, a.frame(3).rgb)


def test_jpeg_alone_is_a_small_lossy_change():
    base = SynthConfig.preset("dynamic-small", seed=2, frames=6, **SMALL)
    a, b = build_scene(base).frame(2).rgb, build_scene(base.replace(jpeg_quality=60)).frame(2).rgb
    diff = np.abs(a.astype(float) - b)
    assert 0.3 < diff.mean() < 12.0 and not np.array_equal(a, b)  # 160x120 is all fine detail
    c = build_scene(base.replace(jpeg_quality=95)).frame(2).rgb
    assert np.abs(a.astype(float) - c).mean() < diff.mean()
