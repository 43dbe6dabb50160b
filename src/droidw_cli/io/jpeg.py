"""In-memory JPEG for images the tracker keeps for later (keyframe images and thumbnails).

A 96 × 128 RGB thumbnail is 37 KB raw and about 5-8 KB as JPEG at quality
95; a 10-minute video keeps a couple of thousand of them.
"""

from __future__ import annotations

import cv2
import numpy as np


def encode_rgb(image: np.ndarray, quality: int) -> np.ndarray:
    """RGB (H, W, 3) or grey (H, W) uint8 → JPEG bytes as a uint8 array."""
    bgr = image[..., ::-1] if image.ndim == 3 else image
    ok, data = cv2.imencode(".jpg", np.ascontiguousarray(bgr), [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise RuntimeError("JPEG encoding of a keyframe image failed")
    return data


def decode_rgb(data: np.ndarray) -> np.ndarray:
    """Inverse of :func:`encode_rgb` (up to the JPEG loss)."""
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    return np.ascontiguousarray(image[..., ::-1]) if image.ndim == 3 else image
