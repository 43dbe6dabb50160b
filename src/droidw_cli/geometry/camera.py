"""Pinhole camera conventions shared by every module.

Pixel centres sit at integer coordinates: pixel (u, v) covers
[u − ½, u + ½] × [v − ½, v + ½].  Averaging s×s blocks (``cv2.INTER_AREA``)
maps full-resolution pixel x to grid coordinate (x + ½)/s − ½, so the
intrinsics of a grid downsampled by s are

    f' = f / s,    c' = (c + ½) / s − ½.

The BA works on the 1/8 grid (s = 8).
"""

from __future__ import annotations

import numpy as np

BA_SCALE = 8  # the BA grid is 1/8 of the working resolution


def scale_intrinsics(intrinsics, scale: float):
    """Intrinsics ``[fx, fy, cx, cy]`` of an image resized by ``1/scale`` (area averaging).

    Works for numpy arrays and torch tensors (anything supporting arithmetic).
    """
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    out = [fx / scale, fy / scale, (cx + 0.5) / scale - 0.5, (cy + 0.5) / scale - 0.5]
    if isinstance(intrinsics, np.ndarray):
        return np.array(out, dtype=intrinsics.dtype)
    try:
        import torch

        if isinstance(intrinsics, torch.Tensor):
            return torch.stack([torch.as_tensor(v) for v in out]).to(intrinsics)
    except ImportError:  # pragma: no cover - torch is a hard dependency
        pass
    return out


def working_size(height: int, width: int, target_area: int, multiple: int = BA_SCALE) -> tuple[tuple[int, int], tuple[int, int]]:
    """The resize and crop that bring an image to about ``target_area`` pixels.

    The aspect ratio is kept; the resized image is then centre-cropped so that
    both sides are multiples of ``multiple``.  Returns ((resized_h, resized_w),
    (crop_h, crop_w)).
    """
    if height <= 0 or width <= 0:
        raise ValueError("image size must be positive")
    s = np.sqrt(target_area / float(height * width))
    rh, rw = max(multiple, int(round(height * s))), max(multiple, int(round(width * s)))
    return (rh, rw), (rh - rh % multiple, rw - rw % multiple)


def resize_crop_intrinsics(intrinsics, src_hw: tuple[int, int], resized_hw: tuple[int, int], crop_hw: tuple[int, int]) -> np.ndarray:
    """Intrinsics after resizing ``src_hw`` → ``resized_hw`` and centre-cropping to ``crop_hw``."""
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    sy, sx = resized_hw[0] / src_hw[0], resized_hw[1] / src_hw[1]
    oy, ox = (resized_hw[0] - crop_hw[0]) // 2, (resized_hw[1] - crop_hw[1]) // 2
    return np.array([fx * sx, fy * sy, (cx + 0.5) * sx - 0.5 - ox, (cy + 0.5) * sy - 0.5 - oy], dtype=np.float64)


def unscale_intrinsics(intrinsics, scale: float):
    """Inverse of :func:`scale_intrinsics`: f = s·f', c = s·(c' + ½) − ½."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    return np.array([fx * scale, fy * scale, (cx + 0.5) * scale - 0.5, (cy + 0.5) * scale - 0.5], dtype=np.float64)
