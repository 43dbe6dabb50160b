"""The XFeat network (Potje et al., "XFeat: Accelerated Features for
Lightweight Image Matching", CVPR 2024), written from the published
architecture.

Every convolution unit is conv → BatchNorm (no affine) → ReLU.  With a
grayscale image x normalised per image (InstanceNorm):

    x1 = block1(x)                               1/4,  24 ch
    x2 = block2(x1 + skip1(x))                   1/4,  24 ch   skip1 = AvgPool(4) + 1×1 conv
    x3 = block3(x2)                              1/8,  64 ch
    x4 = block4(x3)                              1/16, 64 ch
    x5 = block5(x4)                              1/32, 64 ch
    F  = fusion(x3 + up(x4) + up(x5))            1/8,  64 ch   up = bilinear to the 1/8 size

plus a reliability heatmap head on F, a keypoint head on the 8×8
space-to-depth of x, and a fine-matching MLP (kept so that the published
weights load strictly; droidw only uses F).  The attribute names follow the
published state dict so that ``load_state_dict(strict=True)`` works.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


class ConvUnit(nn.Module):
    """Conv2d (no bias) → BatchNorm2d (affine=False) → ReLU, stored as ``layer``."""

    def __init__(self, cin: int, cout: int, kernel: int = 3, stride: int = 1, padding: int = 1) -> None:
        super().__init__()
        self.layer = nn.Sequential(
            nn.Conv2d(cin, cout, kernel, stride=stride, padding=padding, bias=False),
            nn.BatchNorm2d(cout, affine=False),
            nn.ReLU(inplace=True),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.layer(x)


def _units(*specs: tuple) -> nn.Sequential:
    """A chain of :class:`ConvUnit`; each spec is (cin, cout) for 3×3, or (cin, cout, stride), or (cin, cout, 1, 'pw') for 1×1."""
    mods = []
    for spec in specs:
        if len(spec) == 4:  # pointwise
            mods.append(ConvUnit(spec[0], spec[1], kernel=1, stride=1, padding=0))
        else:
            mods.append(ConvUnit(spec[0], spec[1], stride=spec[2] if len(spec) > 2 else 1))
    return nn.Sequential(*mods)


def _mlp(dims: list[int]) -> nn.Sequential:
    """Linear → BatchNorm1d (no affine) → ReLU between layers, a plain Linear at the end."""
    mods: list[nn.Module] = []
    for k in range(len(dims) - 2):
        mods += [nn.Linear(dims[k], dims[k + 1]), nn.BatchNorm1d(dims[k + 1], affine=False), nn.ReLU(inplace=True)]
    mods.append(nn.Linear(dims[-2], dims[-1]))
    return nn.Sequential(*mods)


class XFeatNet(nn.Module):
    """XFeat backbone and heads.  :meth:`dense` gives the 64-channel 1/8 features."""

    DIM = 64
    DOWNSAMPLE = 32  # the deepest level is at 1/32

    def __init__(self) -> None:
        super().__init__()
        self.norm = nn.InstanceNorm2d(1)
        self.skip1 = nn.Sequential(nn.AvgPool2d(4, stride=4), nn.Conv2d(1, 24, 1, stride=1, padding=0))
        self.block1 = _units((1, 4), (4, 8, 2), (8, 8), (8, 24, 2))
        self.block2 = _units((24, 24), (24, 24))
        self.block3 = _units((24, 64, 2), (64, 64), (64, 64, 1, "pw"))
        self.block4 = _units((64, 64, 2), (64, 64), (64, 64))
        self.block5 = _units((64, 128, 2), (128, 128), (128, 128), (128, 64, 1, "pw"))
        self.block_fusion = nn.Sequential(ConvUnit(64, 64), ConvUnit(64, 64), nn.Conv2d(64, 64, 1, padding=0))
        self.heatmap_head = nn.Sequential(
            ConvUnit(64, 64, 1, padding=0), ConvUnit(64, 64, 1, padding=0), nn.Conv2d(64, 1, 1), nn.Sigmoid()
        )
        self.keypoint_head = nn.Sequential(
            ConvUnit(64, 64, 1, padding=0), ConvUnit(64, 64, 1, padding=0), ConvUnit(64, 64, 1, padding=0), nn.Conv2d(64, 65, 1)
        )
        self.fine_matcher = _mlp([128, 512, 512, 512, 512, 64])

    def normalize_input(self, images: torch.Tensor) -> torch.Tensor:
        """(B, C, H, W) image → (B, 1, H, W) grayscale (channel mean), zero mean and unit variance per image."""
        return self.norm(images.mean(dim=1, keepdim=True))

    def dense(self, x: torch.Tensor) -> torch.Tensor:
        """Fused features (B, 64, H/8, W/8) of a normalised grayscale x (B, 1, H, W); H, W multiples of 32.  Not L2-normalised."""
        x1 = self.block1(x)
        x2 = self.block2(x1 + self.skip1(x))
        x3 = self.block3(x2)
        x4 = self.block4(x3)
        x5 = self.block5(x4)
        size = (x3.shape[-2], x3.shape[-1])
        x4 = F.interpolate(x4, size, mode="bilinear", align_corners=False)
        x5 = F.interpolate(x5, size, mode="bilinear", align_corners=False)
        return self.block_fusion(x3 + x4 + x5)

    def heads(self, x: torch.Tensor, feats: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Keypoint logits (B, 65, H/8, W/8) and reliability heatmap (B, 1, H/8, W/8).

        The keypoint head sees the 8×8 space-to-depth of the normalised image x
        (64 channels per cell); the heatmap head sees the fused features.
        """
        cells = F.pixel_unshuffle(x, 8)
        return self.keypoint_head(cells), self.heatmap_head(feats)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.dense(x)
