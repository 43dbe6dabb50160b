"""The rasteriser interface, and the choice of an implementation (as the BA backends are chosen).

A :class:`Rasteriser` renders :class:`~droidw_cli.gaussians.model.Gaussians` through a
:class:`~droidw_cli.gaussians.camera.Camera` into colour, depth and accumulated opacity, differentiably.
``torch`` (:mod:`.torch_raster`) runs anywhere; ``gsplat`` (:mod:`.gsplat_raster`) needs a CUDA device and the
``gsplat`` package.  ``auto`` takes the first of :data:`AUTO_ORDER` that is available here and says why it
passed over the others.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from importlib import import_module

import torch

from droidw_cli.errors import UserError

#: name → "module:Class"
RASTERISERS = {"torch": "droidw_cli.gaussians.torch_raster:TorchRasteriser",
               "gsplat": "droidw_cli.gaussians.gsplat_raster:GsplatRasteriser"}
AUTO_ORDER = ("gsplat", "torch")


@dataclass
class RenderOutput:
    """``colour`` (H, W, 3), ``depth`` (H, W) = Σ zᵢ wᵢ, ``alpha`` (H, W) = Σ wᵢ (wᵢ the compositing weights),
    ``pairs`` (pixel-Gaussian pairs composited), ``radius`` (N,) footprint radii in pixels (0: not seen)."""

    colour: torch.Tensor
    depth: torch.Tensor
    alpha: torch.Tensor
    pairs: int
    radius: torch.Tensor


class Rasteriser(ABC):
    """Renders Gaussians; subclasses set ``name`` and may refuse in :meth:`availability`."""

    name = "?"

    @classmethod
    def availability(cls) -> tuple[bool, str]:
        return True, ""

    @abstractmethod
    def render(self, g, cam, background=(0.0, 0.0, 0.0)) -> RenderOutput: ...


def _load(name: str) -> type[Rasteriser]:
    if name not in RASTERISERS:
        raise UserError(f"unknown rasteriser '{name}' (known: auto, {', '.join(RASTERISERS)})")
    module, _, attr = RASTERISERS[name].partition(":")
    return getattr(import_module(module), attr)


def resolve_rasteriser(name: str = "auto") -> tuple[Rasteriser, str]:
    """A rasteriser and one line saying how it was chosen, e.g. ``torch (auto; gsplat: no CUDA device)``."""
    if name == "auto":
        passed = []
        for candidate in AUTO_ORDER:
            try:
                cls = _load(candidate)
                ok, reason = cls.availability()
            except Exception as exc:  # a broken optional package must not stop the CPU path
                ok, reason = False, f"{type(exc).__name__}: {exc}"
            if ok:
                return cls(), f"{candidate} (auto{''.join('; ' + p for p in passed)})"
            passed.append(f"{candidate}: {reason}")
        raise UserError("no rasteriser can run here: " + "; ".join(passed))
    cls = _load(name)
    ok, reason = cls.availability()
    if not ok:
        raise UserError(f"rasteriser '{name}' cannot run here ({reason}); use --rasteriser torch")
    return cls(), name
