"""Photometric realism applied to a rendered colour image: gain drift, flicker, noise, JPEG.

The textures hold display (sRGB-encoded) values c ∈ [0, 255].  Light adds up
in *linear* intensity, so exposure effects (motion blur, gain) are applied to

    ℓ = srgb⁻¹(c / 255),   srgb⁻¹(x) = x / 12.92            (x ≤ 0.04045)
                                      ((x + 0.055) / 1.055)^2.4  (otherwise)

and the result is encoded back with srgb(ℓ) = 12.92 ℓ (ℓ ≤ 0.0031308), else
1.055 ℓ^(1/2.4) − 0.055, after clipping ℓ to [0, 1] (a saturated sensor).
The encoding is a table over ℓ = i / 65535 (nearest entry): its slope is at
most 12.92 · 255 grey levels per unit, so the table errs by < 0.03 grey levels.

Per frame k, at time t_k = k / fps, in this order:

1. gain  g_k = (1 + gain_drift · w(t_k)) · (1 + flicker · n_k), with
   w(t) = 0.7 sin(ω₁t + φ₁) + 0.3 sin(ω₂t + φ₂) (periods ≈ 9 s and 4.3 s,
   |w| ≤ 1) and n_k a standard normal drawn from (seed, TAG_GAIN, k):
   ℓ ← g_k ℓ;
2. noise: c ← c + noise_std · N(0, 1) per pixel and channel, drawn from
   (seed, TAG_NOISE, k) exactly as before these options existed; then
   rounded and clipped to uint8;
3. JPEG: an OpenCV encode/decode at ``jpeg_quality`` (libjpeg is
   deterministic, so the bytes are too).

With no blur and g_k = 1 the image never leaves uint8 before the noise, so
the default output is unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from droidw_cli.synth import layout
from droidw_cli.synth.config import SynthConfig
from droidw_cli.synth.paths import Wave


def _decode_table() -> np.ndarray:
    x = np.arange(256, dtype=np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def _encode_table() -> np.ndarray:
    lin = np.arange(ENCODE_STEPS + 1, dtype=np.float64) / ENCODE_STEPS
    return (255.0 * np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055)).astype(np.float32)


ENCODE_STEPS = 65535
SRGB_TO_LINEAR = _decode_table()  # (256,) float32
LINEAR_TO_SRGB = _encode_table()  # (65536,) float32, display values 0-255


def to_linear(rgb: np.ndarray) -> np.ndarray:
    """uint8 sRGB → float32 linear intensity in [0, 1] (a table look-up)."""
    return cv2.LUT(rgb, SRGB_TO_LINEAR)


def to_display(lin: np.ndarray) -> np.ndarray:
    """float32 linear intensity → sRGB in [0, 255] as float32 (not rounded); clips to [0, 1] first."""
    scaled = np.clip(lin * np.float32(ENCODE_STEPS) + np.float32(0.5), 0.0, np.float32(ENCODE_STEPS))
    return LINEAR_TO_SRGB.take(scaled.astype(np.uint16))


def jpeg_roundtrip(rgb: np.ndarray, quality: int) -> np.ndarray:
    """Encode an RGB uint8 image as JPEG at ``quality`` with OpenCV and decode it again."""
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("OpenCV could not encode a JPEG")
    return cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)


@dataclass(frozen=True)
class Photometric:
    """The per-frame photometric chain of a :class:`SynthConfig` (see the module docstring)."""

    seed: int
    fps: float
    gain_drift: float
    flicker: float
    noise_std: float
    jpeg_quality: int
    drift: Wave

    @staticmethod
    def of(cfg: SynthConfig) -> "Photometric":
        drift = Wave.random(np.random.default_rng([cfg.seed, layout.TAG_GAIN]), [0.7, 0.3], [9.0, 4.3])
        return Photometric(int(cfg.seed), float(cfg.fps), float(cfg.gain_drift), float(cfg.flicker),
                           float(cfg.noise_std), int(cfg.jpeg_quality), drift)

    def gain(self, k: int) -> float:
        """The exposure gain g_k of frame k (1.0 when gain_drift and flicker are 0)."""
        g = 1.0
        if self.gain_drift > 0:
            g *= 1.0 + self.gain_drift * float(self.drift(k / self.fps))
        if self.flicker > 0:
            rng = np.random.default_rng([self.seed, layout.TAG_GAIN, int(k)])
            g *= 1.0 + self.flicker * float(rng.standard_normal())
        return max(g, 0.0)

    def finish(self, k: int, rgb: np.ndarray, linear: np.ndarray | None = None) -> np.ndarray:
        """The final uint8 RGB of frame k from its render ``rgb`` (uint8), or from ``linear`` (float32
        linear intensity, e.g. an exposure average) when given."""
        g = self.gain(k)
        if linear is None and g == 1.0:
            out = rgb  # uint8 all the way: the output of the defaults is unchanged
        else:
            lin = to_linear(rgb) if linear is None else linear
            out = to_display(lin * np.float32(g) if g != 1.0 else lin)
        if self.noise_std > 0:
            rng = np.random.default_rng([self.seed, layout.TAG_NOISE, int(k)])
            noise = rng.standard_normal(out.shape, dtype=np.float32) * np.float32(self.noise_std)
            out = out + noise
        if out.dtype != np.uint8:
            out = np.clip(np.rint(out), 0, 255).astype(np.uint8)
        if self.jpeg_quality > 0:
            out = jpeg_roundtrip(out, self.jpeg_quality)
        return out
