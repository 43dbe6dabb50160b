"""The motion filter: which frames become keyframe candidates.

A frame is a candidate when the mean optical flow from the last keyframe is
at least ``thresh`` pixels of the 1/8 BA grid (DROID's unit: 3 grid px is
24 px at a 384×512 working size), or when ``max_gap`` frames have passed.  Before initialisation the test uses the *median* flow,
so a fixed camera watching movers (whose pixels are a minority) never produces
a map from people walking by; after ``max_gap`` frames it is enough that the
lower quartile of the flow reaches ``init_min_quartile`` grid px: three
quarters of the image moved, which a near-still camera that wobbles does and
a fixed camera does not, however close its movers come.

The flow here is a cheap DIS FAST estimate on a half-size grey image (ULTRAFAST
at 1/4 size reads 1-5 px of spurious mean flow on a fixed camera watching
pedestrians).  With ``correspondence.coarsest_scale`` k > 0 its pyramid reaches
1/2^k of the working size, as the tracker's other flows do
(:func:`~droidw_cli.correspondence.dis.calc_deep`; level k − 1 of the half-size image).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from droidw_cli.config import MotionFilterConfig
from droidw_cli.correspondence.dis import calc_deep, dis_objects, level_at
from droidw_cli.geometry.camera import BA_SCALE

_SCALE = 2  # the filter's flow runs at 1/2 of the working resolution


def grey_small(image: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) → grey uint8 at 1/_SCALE size (area averaging)."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return cv2.resize(grey, (grey.shape[1] // _SCALE, grey.shape[0] // _SCALE), interpolation=cv2.INTER_AREA)


@dataclass(frozen=True)
class FlowStats:
    """Flow magnitude statistics in grid pixels (working-resolution px / 8)."""

    mean: float
    median: float
    quartile: float = float("nan")  # the lower quartile, when asked for


class MotionFilter:
    """Decides keyframe candidates from flow to the last keyframe."""

    def __init__(self, cfg: MotionFilterConfig, coarsest_scale: int = 0):
        self.cfg = cfg
        self._dis = dis_objects("fast")  # DIS FAST, as calc_deep asks for it
        self._level = level_at(coarsest_scale, _SCALE)
        self._last: np.ndarray | None = None
        self._checked: tuple[np.ndarray, np.ndarray] | None = None  # (image, its small grey) of the last check
        self._since = 0

    def flow_stats(self, grey_a: np.ndarray, grey_b: np.ndarray, quartile: bool = False) -> FlowStats:
        flow = calc_deep(self._dis, grey_a, grey_b, None, self._level)
        mag = cv2.magnitude(flow[..., 0], flow[..., 1]) * (_SCALE / BA_SCALE)  # np.linalg.norm: 15× slower
        if not quartile:
            return FlowStats(float(mag.mean()), float(np.median(mag)))
        low, median = np.percentile(mag, [25, 50])
        return FlowStats(float(mag.mean()), float(median), float(low))

    def check(self, image: np.ndarray, initialised: bool) -> tuple[bool, FlowStats]:
        """Is this frame a keyframe candidate?  The first frame always is."""
        grey = grey_small(image)
        self._checked = (image, grey)
        if self._last is None:
            return True, FlowStats(0.0, 0.0)
        self._since += 1
        floor = self.cfg.init_min_quartile
        waited = not initialised and floor > 0 and self._since >= self.cfg.max_gap
        stats = self.flow_stats(self._last, grey, quartile=waited)
        if initialised:
            ok = stats.mean >= self.cfg.thresh or self._since >= self.cfg.max_gap
        else:
            ok = stats.median >= self.cfg.thresh or (waited and stats.quartile >= floor)
        return ok, stats

    def accept(self, image: np.ndarray) -> None:
        """Make this frame the reference (it became a keyframe)."""
        checked = self._checked
        self._last = checked[1] if checked is not None and checked[0] is image else grey_small(image)
        self._checked = None
        self._since = 0
