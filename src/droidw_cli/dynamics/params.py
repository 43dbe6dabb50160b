"""Tuning knobs of the scene-consistency dynamic detector (beyond ``DynamicsConfig``).

``DynamicsConfig`` (config.py) carries the user-facing ``tau_scale``;
:class:`DetectionParams` holds the rest, with defaults chosen for the 1/8 BA
grid.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DetectionParams:
    """Parameters of :func:`droidw_cli.dynamics.detect.detect_dynamic` and its stages.

    Warping:
        min_depth: points closer than this (metres, in either camera) are invalid.
        depth_mode: how D̂ is read from the source: "closest" (of the bilinear sample
            and its four corners, the depth nearest the observation) or "bilinear"; see warp.py.
    Thresholds (τ = max(tau_scale · median error, floor), per source view):
        color_floor: lower bound of τ_I (RGB in [0, 1], Euclidean norm).
        depth_floor: lower bound of τ_D (metres).  Keeps exact synthetic data,
            whose median error is ~0, from flagging rounding noise.
        sign_margin: the dynamic sign test is D − D̂ < −max(sign_margin · D, median D_err)
            (ADD-SLAM: D − D̂ < 0); see consistency.py.
        min_fraction: a pixel is a dynamic seed when it is flagged in at least
            this fraction of the source views in which it is valid (and in at
            least one).
        min_seed_area: seed components smaller than this (pixels) are dropped.
    Region growing (the MobileSAM substitute):
        grow_steps: at most this many 4-neighbour dilation steps.
        depth_step_tol: a pixel is grown from a neighbour only when their depths differ by at most this
            fraction of its own (0: no limit), so a walker does not run into a wall of its colour behind it.
        max_slant: with the grid's focal lengths, a grown pixel's surface faces the camera within
            this many degrees (:func:`droidw_cli.dynamics.refine.surface_slant`; 90 = no limit).
        max_growth: if > 0, a component stops growing once its area reaches
            max_growth × its seed area (a guard against leaks; off by default).
        color_tol: a grown pixel's colour lies within
            max(color_tol, color_spread · RMS seed colour spread) of the seed's mean colour.
        color_spread: see ``color_tol``.
        depth_rel_tol: a grown pixel's depth D satisfies |D − δ| ≤ depth_rel_tol · δ,
            δ the median depth of the seed component.
        min_object_area: final objects smaller than this (pixels) are dropped.
    """

    min_depth: float = 0.05
    depth_mode: str = "closest"
    color_floor: float = 1e-3
    depth_floor: float = 1e-3
    sign_margin: float = 0.05
    min_fraction: float = 0.5
    min_seed_area: int = 2
    # Eight steps without these limits ran from a walker's feet into the floor, whose depth and colour continue
    # theirs (RGB-D stopgo s2: 79 % of the false-positive cells in the bottom 9 of 48 rows, mask precision 0.88),
    # and joined walkers through it.  The floor is seen at about 55-65° (grown floor cells, quartiles), a walker
    # mostly under 45°.  With the slant and depth-step limits growth stops at the floor and at walls behind, and
    # may run longer: RGB-D mask IoU over 8 sequences 0.849 -> 0.900 (docs/benchmarks.md, "Region growing").
    grow_steps: int = 24
    depth_step_tol: float = 0.05
    max_slant: float = 55.0
    max_growth: float = 0.0
    color_tol: float = 0.15
    color_spread: float = 2.5
    depth_rel_tol: float = 0.15
    min_object_area: int = 4

    def __post_init__(self) -> None:
        if not self.min_depth > 0:
            raise ValueError(f"min_depth must be positive, got {self.min_depth}")
        if self.depth_mode not in ("closest", "bilinear"):
            raise ValueError(f"depth_mode must be 'closest' or 'bilinear', got {self.depth_mode!r}")
        if self.color_floor < 0 or self.depth_floor < 0:
            raise ValueError("color_floor and depth_floor must be >= 0")
        if self.sign_margin < 0:
            raise ValueError(f"sign_margin must be >= 0, got {self.sign_margin}")
        if not 0.0 < self.min_fraction <= 1.0:
            raise ValueError(f"min_fraction must be in (0, 1], got {self.min_fraction}")
        if self.max_growth < 0:
            raise ValueError(f"max_growth must be >= 0, got {self.max_growth}")
        if self.grow_steps < 0 or self.min_seed_area < 1 or self.min_object_area < 1:
            raise ValueError("need grow_steps >= 0, min_seed_area >= 1 and min_object_area >= 1")
        if self.depth_step_tol < 0:
            raise ValueError(f"depth_step_tol must be >= 0, got {self.depth_step_tol}")
        if not 0 < self.max_slant <= 90:
            raise ValueError(f"max_slant must be in (0, 90] degrees, got {self.max_slant}")
        if self.color_tol < 0 or self.color_spread < 0 or self.depth_rel_tol < 0:
            raise ValueError("color_tol, color_spread and depth_rel_tol must be >= 0")
