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


class JpegStack:
    """A (K, H, W, 3) uint8 stack of images kept JPEG-encoded, each decoded when it is read.

    The tracker's result holds its keyframe thumbnails this way: decoded all at
    once they are 37 KB a keyframe at 96 × 128 (77 MB for a 10-minute video),
    encoded a fifth of that, and they are only needed when the run is written.
    ``stack[k]`` decodes one image; ``np.asarray(stack)`` (what ``np.savez``
    does) decodes all of them into one array, equal to the images decoded one by one.
    """

    def __init__(self, data: list[np.ndarray], image_shape: tuple[int, ...]):
        self._data = list(data)
        self.shape = (len(self._data), *image_shape)
        self.dtype = np.dtype(np.uint8)
        self.ndim = len(self.shape)

    def __len__(self) -> int:
        return len(self._data)

    def __getitem__(self, k):
        if isinstance(k, slice):
            return np.asarray(JpegStack(self._data[k], self.shape[1:]))
        return decode_rgb(self._data[k])

    def __iter__(self):
        return (decode_rgb(d) for d in self._data)

    @property
    def nbytes_encoded(self) -> int:
        return sum(d.nbytes for d in self._data)

    def __array__(self, dtype=None, copy=None):
        out = np.empty(self.shape, np.uint8)
        for k, d in enumerate(self._data):
            out[k] = decode_rgb(d)
        return out if dtype is None else out.astype(dtype, copy=False)
