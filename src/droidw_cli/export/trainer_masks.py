"""The run's 1/8-grid mover masks brought to the input frames, as trainers read masks.

A raw input pixel (u, v) (OpenCV convention: pixel centres at integers) is
undistorted to normalised coordinates x = (u_u − cx) / fx (through the
calibration's radial-tangential distortion, as the run's frame preparation
undistorted the frames), placed in the working image at u' = cx' + fx'·x (the
run's working intrinsics: this covers the resize and the centre crop), and
falls in BA-grid cell ⌊(u' + ½) / 8⌋: cell j spans working pixels 8j … 8j + 7.
Input pixels outside the cropped working image take the nearest cell.

The upsampled mask (nearest cell, no blur) is then grown by ``dilate`` input
pixels (a disc; by default half a grid cell, :func:`default_dilation`), so
that a mover's outline, which a 1/8 cell can cut through, is covered too.  Written as single-channel 8-bit images: **0 (black) = ignore**
(a mover), 255 (white) = static, which is what nerfstudio's ``mask_path`` and
COLMAP's ``masks/`` folder read.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from droidw_cli.io.calibration import Calibration


@dataclass(frozen=True)
class GridLookup:
    """For every input pixel (H, W) the BA-grid row and column it falls in."""

    rows: np.ndarray
    cols: np.ndarray

    def upsample(self, grid_mask: np.ndarray) -> np.ndarray:
        """(h, w) bool grid mask → (H, W) bool at the input size (nearest cell)."""
        return np.asarray(grid_mask, dtype=bool)[self.rows, self.cols]


def normalised_coordinates(calib: Calibration, size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """(H, W) normalised, undistorted camera coordinates x, y of every raw input pixel centre."""
    h, w = size
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    if not calib.has_distortion:
        return (u - calib.cx) / calib.fx, (v - calib.cy) / calib.fy
    pts = np.stack([u.ravel(), v.ravel()], -1).reshape(-1, 1, 2)
    norm = cv2.undistortPoints(pts, calib.camera_matrix(), np.asarray(calib.distortion, np.float64))
    norm = norm.reshape(h, w, 2)
    return norm[..., 0], norm[..., 1]


def grid_lookup(calib: Calibration, size: tuple[int, int], work_intrinsics, grid_hw: tuple[int, int],
                grid_scale: int = 8) -> GridLookup:
    """The grid cell of every input pixel (module docstring); ``work_intrinsics`` fx fy cx cy at the working size."""
    fxw, fyw, cxw, cyw = (float(v) for v in work_intrinsics)
    x, y = normalised_coordinates(calib, size)
    gh, gw = grid_hw
    cols = np.clip(np.floor((cxw + fxw * x + 0.5) / grid_scale), 0, gw - 1).astype(np.intp)
    rows = np.clip(np.floor((cyw + fyw * y + 0.5) / grid_scale), 0, gh - 1).astype(np.intp)
    return GridLookup(rows, cols)


def default_dilation(calib: Calibration, work_intrinsics, grid_scale: int = 8) -> int:
    """Half a BA-grid cell in input pixels: the default growth of the movers (``--mask-dilate``)."""
    return max(1, int(round(0.5 * grid_scale * calib.fx / float(work_intrinsics[0]))))


def mask_image(mover: np.ndarray, dilate: int) -> np.ndarray:
    """(H, W) bool movers → uint8 image, 0 on the movers grown by ``dilate`` pixels, 255 elsewhere."""
    grown = mover.astype(np.uint8)
    if dilate > 0 and grown.any():
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate + 1, 2 * dilate + 1))
        grown = cv2.dilate(grown, kernel)
    return np.where(grown > 0, 0, 255).astype(np.uint8)
