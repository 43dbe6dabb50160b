"""Bring raw frames to the working resolution: undistort, resize, centre-crop to a multiple of 8.

For a source of H×W pixels, :func:`~droidw_cli.geometry.camera.working_size`
gives the resized size (rh, rw) ≈ (H, W)·√(target_area / HW) and the crop
(ch, cw) = (rh − rh mod 8, rw − rw mod 8), taken from the centre (offset
((rh − ch) // 2, (rw − cw) // 2)).  Under the pixel-centre convention the
intrinsics become

    fx' = fx · sx,   cx' = (cx + ½) · sx − ½ − ox,   sx = rw / W

(likewise for y), see :func:`~droidw_cli.geometry.camera.resize_crop_intrinsics`.

With distortion coefficients the image is first undistorted at full
resolution onto the same camera matrix K (``cv2.initUndistortRectifyMap``
once, ``cv2.remap`` per frame), so the intrinsics above stay valid and the
prepared calibration has no distortion.  Colour is resized with
``INTER_AREA`` when shrinking and ``INTER_LINEAR`` when enlarging; depth with
nearest-neighbour (``INTER_NEAREST_EXACT``, which samples pixel centres) so that
no depth is invented across edges and 0 (invalid) stays 0.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from droidw_cli.geometry.camera import resize_crop_intrinsics, working_size
from droidw_cli.io.calibration import Calibration
from droidw_cli.io.frames import Frame


class FramePreparer:
    """Prepares frames of one source size.

    ``intrinsics`` may be a :class:`Calibration` (its distortion is used unless
    ``distortion`` is given) or ``(fx, fy, cx, cy)`` at source resolution, or
    None (unknown; ``.intrinsics`` is then None).  Exposes ``size`` (working
    H, W), ``resized_size``, ``offset`` (crop origin y, x in the resized
    image), ``intrinsics`` (4,) at working resolution and ``calibration``.
    """

    def __init__(self, src_hw: tuple[int, int], intrinsics=None, target_area: int = 384 * 512, distortion=None) -> None:
        import cv2

        h, w = (int(v) for v in src_hw)
        if h <= 0 or w <= 0:
            raise ValueError(f"source size must be positive, got {src_hw}")
        if target_area <= 0:
            raise ValueError(f"target_area must be positive, got {target_area}")
        if isinstance(intrinsics, Calibration):
            if distortion is None:
                distortion = intrinsics.distortion
            intrinsics = intrinsics.as_array()
        dist = np.asarray(distortion if distortion is not None else (), dtype=np.float64).ravel()
        if dist.size not in (0, 4, 5, 8, 12, 14):
            raise ValueError(f"distortion must have 4 or 5 coefficients (k1 k2 p1 p2 [k3]), got {dist.size}")
        self.src_size = (h, w)
        self.resized_size, self.size = working_size(h, w, target_area)
        rh, rw = self.resized_size
        self.offset = ((rh - self.size[0]) // 2, (rw - self.size[1]) // 2)
        self._identity_resize = self.resized_size == self.src_size
        self._interp = cv2.INTER_AREA if rh * rw < h * w else cv2.INTER_LINEAR
        self.source_intrinsics = None if intrinsics is None else np.asarray(intrinsics, dtype=np.float64).reshape(4)
        self.intrinsics = None
        if self.source_intrinsics is not None:
            self.intrinsics = resize_crop_intrinsics(self.source_intrinsics, self.src_size, self.resized_size, self.size)
        self._maps = None
        if dist.size and np.any(dist != 0):
            if self.source_intrinsics is None:
                raise ValueError("undistortion needs the intrinsics")
            fx, fy, cx, cy = self.source_intrinsics
            k = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1]], dtype=np.float64)
            self._maps = cv2.initUndistortRectifyMap(k, dist, None, k, (w, h), cv2.CV_32FC1)

    @property
    def calibration(self) -> Calibration | None:
        """The working-resolution calibration (no distortion: frames are undistorted)."""
        return None if self.intrinsics is None else Calibration(*(float(v) for v in self.intrinsics))

    def _check(self, array: np.ndarray, what: str) -> None:
        if array.shape[:2] != self.src_size:
            raise ValueError(f"{what} is {array.shape[:2]}, the preparer was made for {self.src_size}")

    def _crop(self, array: np.ndarray) -> np.ndarray:
        oy, ox = self.offset
        return np.ascontiguousarray(array[oy : oy + self.size[0], ox : ox + self.size[1]])

    def image(self, image: np.ndarray) -> np.ndarray:
        """H×W×3 uint8 RGB at source size → working-size RGB uint8."""
        import cv2

        self._check(image, "image")
        if self._maps is not None:
            image = cv2.remap(image, self._maps[0], self._maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
        if not self._identity_resize:
            image = cv2.resize(image, self.resized_size[::-1], interpolation=self._interp)
        return self._crop(image)

    def depth(self, depth: np.ndarray) -> np.ndarray:
        """H×W float32 metres → working size, nearest neighbour (0 = invalid is kept)."""
        import cv2

        self._check(depth, "depth")
        depth = np.asarray(depth, dtype=np.float32)
        if self._maps is not None:
            depth = cv2.remap(depth, self._maps[0], self._maps[1], cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT)
        if not self._identity_resize:
            depth = cv2.resize(depth, self.resized_size[::-1], interpolation=cv2.INTER_NEAREST_EXACT)
        return self._crop(depth)

    def __call__(self, image: np.ndarray, depth: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """Prepared ``(image, depth)``; depth stays None when not given."""
        return self.image(image), (None if depth is None else self.depth(depth))

    def frame(self, frame: Frame) -> Frame:
        """A copy of ``frame`` with prepared image and depth (same index and timestamp)."""
        image, depth = self(frame.image, frame.depth)
        return dataclasses.replace(frame, image=image, depth=depth)


def preparer_for(source, calibration: Calibration | None = None, target_area: int = 384 * 512) -> FramePreparer:
    """A FramePreparer for ``source``: the given calibration, else the source's ``intrinsics_hint``."""
    calib = calibration if calibration is not None else source.intrinsics_hint
    return FramePreparer(source.size, calib, target_area)
