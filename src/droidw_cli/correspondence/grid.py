"""Full-resolution flow ↔ 1/8-grid targets, and input validation.

Convention (see :mod:`droidw_cli.geometry.camera`): grid cell g of the
1/8 grid averages the 8×8 block of full-resolution pixels whose centre is

    x = 8 g + 3.5.

A block's flow is the mean (``INTER_AREA`` downsampling) of the full-res
flow f over the block, f̄, so the target of cell g in frame j is

    p*_ij(g) = (x + f̄ − 3.5) / 8 = g + f̄ / 8.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import torch

BLOCK = 8  # the BA grid is 1/8 of the working resolution


def validate_image(image: np.ndarray, what: str = "image") -> np.ndarray:
    """Check an (H, W, 3) uint8 RGB (or (H, W) gray) image with H, W multiples of 8."""
    if not isinstance(image, np.ndarray):
        raise ValueError(f"{what} must be a numpy array, got {type(image).__name__}")
    if image.dtype != np.uint8:
        raise ValueError(f"{what} must be uint8, got {image.dtype}")
    if not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise ValueError(f"{what} must have shape (H, W, 3) or (H, W), got {image.shape}")
    h, w = image.shape[:2]
    if h <= 0 or w <= 0 or h % BLOCK or w % BLOCK:
        raise ValueError(f"{what} height and width must be positive multiples of {BLOCK}, got {h}x{w}")
    return image


def validate_flow(flow: np.ndarray, hw: tuple[int, int], what: str = "init_flow") -> np.ndarray:
    """Check an (H, W, 2) finite flow and return it as a contiguous float32 copy."""
    flow = np.asarray(flow)
    if flow.shape != (hw[0], hw[1], 2):
        raise ValueError(f"{what} must have shape ({hw[0]}, {hw[1]}, 2), got {flow.shape}")
    flow = np.ascontiguousarray(flow, dtype=np.float32).copy()
    if not np.isfinite(flow).all():
        raise ValueError(f"{what} contains non-finite values")
    return flow


def area_downsample(field: np.ndarray, s: int = BLOCK) -> np.ndarray:
    """Mean over s×s blocks of an (H, W) or (H, W, C ≤ 4) float32 array (H, W multiples of s).

    ``cv2.INTER_AREA`` with an integer factor is exactly the block mean.
    """
    h, w = field.shape[:2]
    if h % s or w % s:
        raise ValueError(f"size {h}x{w} is not a multiple of {s}")
    src = np.ascontiguousarray(field, dtype=np.float32)
    return cv2.resize(src, (w // s, h // s), interpolation=cv2.INTER_AREA).reshape(h // s, w // s, *field.shape[2:])


@functools.lru_cache(maxsize=16)
def _grid(h: int, w: int) -> np.ndarray:
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    g = np.stack([xs, ys], axis=-1)
    g.flags.writeable = False
    return g


def cached_grid(h: int, w: int) -> np.ndarray:
    """(h, w, 2) float32 (x, y) = (column, row) coordinates; cached and read-only (do not modify)."""
    return _grid(int(h), int(w))


def grid_coordinates(h: int, w: int) -> np.ndarray:
    """(h, w, 2) float32 array of (x, y) = (column, row) coordinates (a fresh, writable array)."""
    return _grid(int(h), int(w)).copy()


def mean_length(flow: np.ndarray) -> float:
    """Mean ‖f‖ over an (H, W, 2) flow; the same float32 sums as ``np.linalg.norm(flow, axis=-1).mean()``,
    10× faster (numpy's norm over a last axis of two is a slow reduction)."""
    x, y = flow[..., 0], flow[..., 1]
    return float(np.sqrt(x * x + y * y).mean())


def flow_to_target(flow: np.ndarray) -> np.ndarray:
    """Targets p* on the 1/8 grid, (H/8, W/8, 2) float32, from a full-res flow (H, W, 2): g + f̄/8."""
    mean_flow = area_downsample(flow)
    return cached_grid(*mean_flow.shape[:2]) + mean_flow / BLOCK


def target_to_flow(target: np.ndarray | torch.Tensor) -> np.ndarray:
    """Full-resolution flow (H, W, 2) float32 from grid targets (H/8, W/8, 2).

    The grid flow 8 (p* − g) is upsampled bilinearly with the same pixel-centre
    convention (full-res x samples grid coordinate (x − 3.5)/8, clamped at the
    borders), so affine flows are reproduced exactly away from the border.
    Use it to turn correspondences induced by poses and depths into ``init_flow``.
    """
    t = target.detach().cpu().numpy() if isinstance(target, torch.Tensor) else np.asarray(target)
    if t.ndim != 3 or t.shape[2] != 2:
        raise ValueError(f"target must have shape (H/8, W/8, 2), got {t.shape}")
    block_flow = (t.astype(np.float32) - cached_grid(t.shape[0], t.shape[1])) * BLOCK
    size = (t.shape[1] * BLOCK, t.shape[0] * BLOCK)
    return np.ascontiguousarray(cv2.resize(block_flow, size, interpolation=cv2.INTER_LINEAR), dtype=np.float32)
