"""The settings of ``droidw map``: one frozen dataclass (``map.json`` records it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class MapParams:
    """Settings of the Gaussian map (ADD-SLAM's mapping, Sec. "Dynamic-static composite mapping").

    Resolution and data:
      ``size``: (H, W) of the images the map is fitted and evaluated at; None = the run's working size
      divided by ``downscale``.  ``holdout_every``: every N-th non-keyframe is a held-out view (never trained
      on).  ``mask_dilate``: grid cells the dynamic mask is grown by before the static map leaves it out.
      ``use_masks``: False treats every pixel as static (the ablation of ``map_bench.py``).
    Initialisation and densification (ADD-SLAM: new Gaussians where a pixel is not dynamic, has depth, and the
      rendered opacity is below ``densify_alpha`` = 0.8): one Gaussian per ``init_stride``² pixels, of standard
      deviation ``init_sigma`` × stride pixels at its depth, opacity ``init_opacity``.
    Optimisation: ``steps`` Adam steps on the static map (split evenly over the keyframes as they are added,
      then ``refine_fraction`` of them over all keyframes), ``object_steps`` per keyframe with objects; the
      learning rates (ADD-SLAM's: position 1e-3 → 1.6e-6, colour 0.0025, opacity 0.05, scale 0.005, rotation
      0.001; positions are scaled by the scene's median depth, colours here faster); the loss weights
      (colour: (1 − ``ssim_weight``) L1 + ``ssim_weight`` (1 − SSIM), ADD-SLAM's 0.2; depth ``depth_weight``;
      isotropy regulariser ``scale_weight``).
    ``minutes``: the time budget; the run stops early when it is spent (then it is not deterministic:
      ``map.json`` says what ended it).  ``seed``: the random keyframe order.
    """

    size: tuple[int, int] | None = None
    downscale: int = 2
    holdout_every: int = 20
    mask_dilate: int = 1
    use_masks: bool = True
    init_stride: int = 2
    init_sigma: float = 0.6
    init_opacity: float = 0.9
    densify_alpha: float = 0.8
    prune_opacity: float = 0.01
    steps: int = 200
    refine_fraction: float = 0.3
    object_steps: int = 20
    lr_position: float = 1e-3
    lr_position_final: float = 1.6e-6
    lr_colour: float = 0.01
    lr_opacity: float = 0.05
    lr_scale: float = 0.005
    lr_rotation: float = 0.001
    ssim_weight: float = 0.2
    depth_weight: float = 0.1
    scale_weight: float = 10.0
    minutes: float = 8.0
    seed: int = 0
    rasteriser: str = "auto"

    def __post_init__(self) -> None:
        if self.size is not None and (len(self.size) != 2 or min(self.size) < 8):
            raise ValueError(f"size must be H, W of at least 8 pixels, got {self.size}")
        if self.downscale < 1 or self.holdout_every < 1 or self.init_stride < 1:
            raise ValueError("downscale, holdout_every and init_stride must be ≥ 1")
        if self.steps < 1 or self.object_steps < 0:
            raise ValueError("steps must be ≥ 1 and object_steps ≥ 0")
        if not self.minutes > 0:
            raise ValueError(f"the time budget must be positive, got {self.minutes} minutes")

    def to_dict(self) -> dict:
        return asdict(self)
