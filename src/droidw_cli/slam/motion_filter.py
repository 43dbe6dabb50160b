"""The motion filter: which frames become keyframe candidates.

A frame is a candidate when the mean optical flow from the last keyframe is
at least ``thresh`` pixels of the 1/8 BA grid (DROID's unit: 3 grid px is
24 px at a 384×512 working size), or when ``max_gap`` frames have passed.  Before initialisation the test uses the *median* flow,
so a fixed camera watching movers (whose pixels are a minority) never produces
a map from people walking by; after ``max_gap`` frames it is enough that the
lower quartile of the flow reaches ``init_min_quartile`` grid px: three
quarters of the image moved, which a near-still camera that wobbles does and
a fixed camera does not, however close its movers come.  Either way the
median of the flow where the images confirm it (:func:`motion_evidence`)
must reach ``EVIDENCE_MIN``: DIS spreads close movers' motion over a
textureless wall beside them, which then "moves" with them (the fixed preset's
seeds 2 and 4 built a map out of three walkers without this).

Each frame's flow from the keyframe starts from the previous frame's, carried on at constant velocity,
f₀(t) = f(t − 1) · (t − r) / (t − 1 − r) for reference keyframe r (DIS then only refines it).  Without
this start the flow of a camera travelling into the scene at 10 frames/s failed beyond two frames
(the ``drive`` preset: DIS MEDIUM's median error 0.5 px at two frames, 2.9 px at three, 11 px at four),
the mean flow *fell* as the motion grew, no frame became a candidate, and keyframes came only at
``max_gap``, ten metres apart.  Only up to ``max_gap`` frames from the reference: a fixed camera before
initialisation never gets a second keyframe, and on the ``fixed`` preset (seed 2) walkers smeared over a
textureless wall made its flow reach the start's threshold after some 20 frames; from there each start
carried on the last flow, DIS confirmed it where nothing shows, and the median grew to 127 grid px by frame
295 (the identity held, but the motion filter's time went from 2 to 5 ms a frame).  The accepted candidate's flow (:attr:`MotionFilter.accepted_flow`)
then starts the match of the new keyframe's first edge (:mod:`droidw_cli.slam.scout`).

The flow here is a cheap DIS FAST estimate on a half-size grey image (ULTRAFAST
at 1/4 size reads 1-5 px of spurious mean flow on a fixed camera watching
pedestrians).  With ``correspondence.coarsest_scale`` k > 0 its pyramid reaches
1/2^k of the working size, as the tracker's other flows do
(:func:`~droidw_cli.correspondence.dis.calc_deep`; level k − 1 of the half-size image).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from droidw_cli.config import MotionFilterConfig
from droidw_cli.correspondence.dis import calc_deep, dis_objects, level_at
from droidw_cli.geometry.camera import BA_SCALE

_SCALE = 2  # the filter's flow runs at 1/2 of the working resolution
#: motion evidence (before initialisation): the window (half-size px) and how much of the no-motion error,
#: in grey levels, the flow must explain
EVIDENCE_BLOCK = 8
EVIDENCE_LEVELS = 2.0
#: grid px: before initialisation a candidate also needs this median of the evidenced flow
EVIDENCE_MIN = 0.25
#: grid px: the next frame's flow starts from this one's, carried on, when its median carried on to the next frame
#: reaches this (20 px at the working size, where DIS alone begins to lose pixels on the drive preset).  The
#: median, not the mean, and only then: a walker close in front of a near-still camera (the wobble preset) moves
#: fast, and starting every frame from the last changed that preset's keyframes for nothing (0.24 → 0.46 cm on
#: seed 1)
START_MIN = 2.5


def grey_small(image: np.ndarray) -> np.ndarray:
    """RGB uint8 (H, W, 3) → grey uint8 at 1/_SCALE size (area averaging)."""
    grey = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    return cv2.resize(grey, (grey.shape[1] // _SCALE, grey.shape[0] // _SCALE), interpolation=cv2.INTER_AREA)


def motion_evidence(grey_a: np.ndarray, grey_b: np.ndarray, flow: np.ndarray, block: int = EVIDENCE_BLOCK) -> np.ndarray:
    """(h, w) bool: where the flow a → b explains image b better than no motion, per ``block`` × ``block`` window.

    With e_flow = mean |b(x + f(x)) − a(x)| and e_zero = mean |b(x) − a(x)| over the window, the flow is
    evidenced where e_zero − e_flow > ``EVIDENCE_LEVELS`` grey levels.  A textureless wall reads the same
    whatever the flow claims (DIS fills it in from the movers beside it: on the fixed preset, seed 2, a cloudy
    wall "moved" 2-4 grid px with three walkers close in front), and a static textured patch given a wrong flow
    is explained better by no motion; only pixels whose change the flow accounts for count as moving.
    """
    h, w = grey_a.shape
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    a = grey_a.astype(np.float32)
    warped = cv2.remap(grey_b, gx + flow[..., 0], gy + flow[..., 1], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_REPLICATE).astype(np.float32)
    e_flow = cv2.blur(cv2.absdiff(warped, a), (block, block))
    e_zero = cv2.blur(cv2.absdiff(grey_b.astype(np.float32), a), (block, block))
    return e_zero - e_flow > EVIDENCE_LEVELS


@dataclass(frozen=True)
class FlowStats:
    """Flow magnitude statistics in grid pixels (working-resolution px / 8)."""

    mean: float
    median: float
    quartile: float = float("nan")  # the lower quartile, when asked for
    evidenced: float = float("nan")  # the median where the flow is evidenced (motion_evidence), when asked for


def _with_evidence(stats: FlowStats, grey_a: np.ndarray, grey_b: np.ndarray, flow: np.ndarray,
                   mag: np.ndarray) -> FlowStats:
    """``stats`` with the median of the flow magnitude ``mag`` where :func:`motion_evidence` holds (zero elsewhere)."""
    shown = float(np.median(np.where(motion_evidence(grey_a, grey_b, flow), mag, 0.0)))
    return dataclasses.replace(stats, evidenced=shown)


class MotionFilter:
    """Decides keyframe candidates from flow to the last keyframe."""

    def __init__(self, cfg: MotionFilterConfig, coarsest_scale: int = 0, keep_every_flow: bool = False):
        self.cfg = cfg
        self._keep_every = keep_every_flow  # accepted_flow also after motions too small to start the next frame
        self._dis = dis_objects("fast")  # DIS FAST, as calc_deep asks for it
        self._level = level_at(coarsest_scale, _SCALE)
        self._last: np.ndarray | None = None
        self._checked: tuple[np.ndarray, np.ndarray] | None = None  # (image, its small grey) of the last check
        self._since = 0
        self._flow_last: np.ndarray | None = None  # the flow reference → the last checked frame (half size), as a start
        self._flow_checked: np.ndarray | None = None  # the same flow, kept whatever its size
        #: the flow (half size, px) from the previous reference to the frame :meth:`accept` took, None for the first
        self.accepted_flow: np.ndarray | None = None

    def flow_stats(self, grey_a: np.ndarray, grey_b: np.ndarray, quartile: bool = False,
                   evidenced: bool = False) -> FlowStats:
        """Flow statistics a → b; ``evidenced``: also the median of the flow counted only where it explains
        b better than standing still does (:func:`motion_evidence`), zero elsewhere."""
        stats, flow, mag = self._flow(grey_a, grey_b, quartile)
        return _with_evidence(stats, grey_a, grey_b, flow, mag) if evidenced else stats

    def _flow(self, grey_a: np.ndarray, grey_b: np.ndarray, quartile: bool,
              start: np.ndarray | None = None) -> tuple[FlowStats, np.ndarray, np.ndarray]:
        """(statistics without the evidence, the flow a → b (from ``start``), its magnitude in grid px)."""
        flow = calc_deep(self._dis, grey_a, grey_b, start, self._level)
        mag = cv2.magnitude(flow[..., 0], flow[..., 1]) * (_SCALE / BA_SCALE)  # np.linalg.norm: 15× slower
        if not quartile:
            return FlowStats(float(mag.mean()), float(np.median(mag))), flow, mag
        low, median = np.percentile(mag, [25, 50])
        return FlowStats(float(mag.mean()), float(median), float(low)), flow, mag

    def check(self, image: np.ndarray, initialised: bool) -> tuple[bool, FlowStats]:
        """Is this frame a keyframe candidate?  The first frame always is."""
        grey = grey_small(image)
        self._checked = (image, grey)
        if self._last is None:
            return True, FlowStats(0.0, 0.0)
        self._since += 1
        floor = self.cfg.init_min_quartile
        waited = not initialised and floor > 0 and self._since >= self.cfg.max_gap
        start = None
        if self._flow_last is not None and 2 <= self._since <= self.cfg.max_gap:  # constant velocity, not beyond
            start = self._flow_last * np.float32(self._since / (self._since - 1))
        stats, flow, mag = self._flow(self._last, grey, quartile=waited, start=start)
        carried = stats.median * (self._since + 1) / self._since  # the next frame's median at constant velocity
        self._flow_last = flow if carried >= START_MIN else None
        self._flow_checked = flow
        if initialised:
            ok = stats.mean >= self.cfg.thresh or self._since >= self.cfg.max_gap
        else:
            ok = stats.median >= self.cfg.thresh or (waited and stats.quartile >= floor)
            if ok:  # and some of the motion must show in the images, not only in the flow (motion_evidence)
                stats = _with_evidence(stats, self._last, grey, flow, mag)
                ok = stats.evidenced >= EVIDENCE_MIN
        return ok, stats

    def accept(self, image: np.ndarray) -> None:
        """Make this frame the reference (it became a keyframe)."""
        checked = self._checked
        same = checked is not None and checked[0] is image
        self._last = checked[1] if same else grey_small(image)
        kept = self._flow_checked if self._keep_every else self._flow_last
        self.accepted_flow = kept if same and self._since > 0 else None
        self._checked = None
        self._since = 0
        self._flow_last = self._flow_checked = None
