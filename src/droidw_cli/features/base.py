"""The dense feature extractor interface.

A feature extractor maps a batch of RGB images (B, 3, H, W) to dense
descriptors F on the BA grid, (B, C, H/8, W/8), each pixel's descriptor
L2-normalised over the channels, so that cos(F_i, F_j) = F_i · F_j.
DROID-W compares such descriptors across frames to estimate per-pixel
dynamic uncertainty.  Plugins implement :class:`FeatureExtractor` and are
found by name through :func:`droidw_cli.features.registry.get_feature_extractor`.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import torch


class FeatureExtractor(ABC):
    """Dense descriptors at 1/``stride`` of the image resolution.

    Attributes:
        name: the registry name of the extractor.
        channels: C, the descriptor dimension.
        stride: the output is (H/stride, W/stride); droidw's BA grid needs 8.
        device: the torch device the extractor runs on.
    """

    name: str = ""
    channels: int = 0
    stride: int = 8
    device: torch.device = torch.device("cpu")

    @abstractmethod
    def extract(self, images: torch.Tensor) -> torch.Tensor:
        """Descriptors of a batch of images.

        Args:
            images: (B, 3, H, W) RGB, float32 in [0, 1] or uint8 in [0, 255];
                H and W are multiples of ``stride``.

        Returns:
            (B, C, H/stride, W/stride) float32 on ``device``, unit L2 norm over C.
        """

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, channels={self.channels}, stride={self.stride}, device={str(self.device)!r})"


def as_float_images(images: torch.Tensor, stride: int, device: torch.device | str) -> torch.Tensor:
    """Validate a (B, 3, H, W) batch and return it as float32 in [0, 1] on ``device``.

    uint8 input is divided by 255; floating input is taken as already in [0, 1].
    Raises ValueError for a wrong rank, channel count or a size that is not a
    multiple of ``stride``.
    """
    if not isinstance(images, torch.Tensor):
        raise ValueError(f"images must be a torch.Tensor, got {type(images).__name__}")
    if images.ndim != 4 or images.shape[1] != 3:
        raise ValueError(f"images must have shape (B, 3, H, W), got {tuple(images.shape)}")
    h, w = int(images.shape[2]), int(images.shape[3])
    if h <= 0 or w <= 0 or h % stride or w % stride:
        raise ValueError(f"image height and width must be positive multiples of {stride}, got {h}x{w}")
    if images.dtype == torch.uint8:
        return images.to(device=device, dtype=torch.float32) / 255.0
    if not images.is_floating_point():
        raise ValueError(f"images must be uint8 or floating point, got {images.dtype}")
    return images.to(device=device, dtype=torch.float32)
