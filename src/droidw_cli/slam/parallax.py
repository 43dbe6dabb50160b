"""Is there parallax between two views yet?  The initialisation gate.

A camera that only rotates (or a scene that is one plane) moves every pixel
by a homography H: x' ~ H x.  Translation in front of a scene with depth
adds parallax that no homography explains.  So the parallax between two
keyframes is measured as the median residual of their dense flow after the
best homography,

    π(a, b) = q₀.₈_x ‖x + f(x) − H(x)‖ / 8      (grid px),

the 80th percentile over block centres, with H fitted by RANSAC to the flow
there (movers, a minority, are its outliers).  Not the median: one plane (a
room's back wall) can fill more than half the view, and a plane moves by a
homography whatever the camera does.  The flow is cheap: DIS FAST on half-size grey images.
"""

from __future__ import annotations

import cv2
import numpy as np

from droidw_cli.geometry.camera import BA_SCALE

_SCALE = 2  # flow at 1/2 of the working resolution
_BLOCK = 8  # sample the flow every _BLOCK half-size pixels
_RANSAC_PX = 1.0  # inlier threshold, half-size px
#: a room's back wall can fill more than half the view, and a plane is a homography: use a high quantile
QUANTILE = 0.8


def _grey_half(image: np.ndarray) -> np.ndarray:
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) if image.ndim == 3 else image
    return cv2.resize(grey, (grey.shape[1] // _SCALE, grey.shape[0] // _SCALE), interpolation=cv2.INTER_AREA)


def homography_parallax(image_a: np.ndarray, image_b: np.ndarray) -> float:
    """π(a, b) in grid px between two working-resolution images (module docstring)."""
    ga, gb = _grey_half(image_a), _grey_half(image_b)
    flow = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_FAST).calc(ga, gb, None)
    h, w = ga.shape
    ys, xs = np.mgrid[_BLOCK // 2:h:_BLOCK, _BLOCK // 2:w:_BLOCK]
    src = np.stack([xs.ravel(), ys.ravel()], 1).astype(np.float32)
    dst = src + flow[ys.ravel(), xs.ravel()]
    inside = (dst[:, 0] >= 0) & (dst[:, 0] < w) & (dst[:, 1] >= 0) & (dst[:, 1] < h)
    if inside.sum() < 16:
        return 0.0
    src, dst = src[inside], dst[inside]
    hom, _ = cv2.findHomography(src, dst, cv2.RANSAC, _RANSAC_PX, maxIters=500, confidence=0.995)
    if hom is None:
        return 0.0
    pred = cv2.perspectiveTransform(src[None], hom)[0]
    residual = np.linalg.norm(dst - pred, axis=1)
    return float(np.quantile(residual, QUANTILE)) * _SCALE / BA_SCALE
