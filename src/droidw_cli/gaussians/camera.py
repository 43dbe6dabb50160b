"""A pinhole camera with a pose, at one image size.

Pixel centres sit at integer coordinates (as in :mod:`droidw_cli.geometry.camera`); a point X_c = (x, y, z) in the
camera frame (OpenCV axes) projects to u = f_x x / z + c_x, v = f_y y / z + c_y.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


@dataclass(frozen=True)
class Camera:
    """``intrinsics`` fx, fy, cx, cy; ``w2c`` (4, 4) world-to-camera; ``size`` (H, W)."""

    intrinsics: tuple[float, float, float, float]
    w2c: torch.Tensor
    size: tuple[int, int]

    @staticmethod
    def from_c2w(intrinsics, c2w, size, dtype=torch.float32) -> "Camera":
        w2c = np.linalg.inv(np.asarray(c2w, dtype=np.float64))
        return Camera(tuple(float(v) for v in intrinsics), torch.as_tensor(w2c, dtype=dtype), (int(size[0]), int(size[1])))

    def crop(self, y0: int, x0: int, h: int, w: int) -> "Camera":
        """The camera of the window rows y0..y0+h, columns x0..x0+w of this one's image."""
        fx, fy, cx, cy = self.intrinsics
        return Camera((fx, fy, cx - x0, cy - y0), self.w2c, (int(h), int(w)))

    def to(self, dtype) -> "Camera":
        return Camera(self.intrinsics, self.w2c.to(dtype), self.size)
