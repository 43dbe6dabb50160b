"""The segmenter interface: seeds (or a centre prompt) in, whole objects out.

ADD-SLAM prompts MobileSAM with the inscribed-circle centre of each seed
region.  MobileSAM's weights cannot be obtained here, so the step sits behind
a small interface that a promptable segmenter can implement:

    segment(seeds, image, depth, focal=None) → Objects

* ``seeds`` (h, w) bool: the dynamic seed pixels M_ic^d (or a few prompt pixels);
* ``image`` (h, w, 3) colour in [0, 1], ``depth`` (h, w) metres (≤ 0 unknown);
* ``focal`` (f_x, f_y) of this grid in pixels, or None (the grower then has no slant limit);
* the result is labelled objects 1…C with inscribed-circle centres
  (:class:`~droidw_cli.dynamics.refine.Objects`).

The built-in ``grow`` segmenter is :func:`~droidw_cli.dynamics.refine.refine_mask`:
8-connected seed components grown over pixels of similar colour and depth.
A plugin registers a factory under the ``droidw.segmenters`` entry-point
group; the factory takes the :class:`~droidw_cli.dynamics.params.DetectionParams`
and returns an object with a ``segment`` method.  ``dynamics.segmenter``
selects it by name.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Callable, Protocol, runtime_checkable

from torch import Tensor

from droidw_cli.dynamics.params import DetectionParams
from droidw_cli.dynamics.refine import Objects, refine_mask
from droidw_cli.errors import UserError

ENTRY_POINT_GROUP = "droidw.segmenters"


@runtime_checkable
class Segmenter(Protocol):
    """Turns dynamic seeds into whole labelled objects."""

    def segment(self, seeds: Tensor, image: Tensor, depth: Tensor,
                focal: tuple[float, float] | None = None) -> Objects: ...


class RegionGrower:
    """The built-in segmenter: region growing of the seed components (see :mod:`~droidw_cli.dynamics.refine`)."""

    name = "grow"

    def __init__(self, params: DetectionParams | None = None) -> None:
        self.params = params or DetectionParams()

    def segment(self, seeds: Tensor, image: Tensor, depth: Tensor,
                focal: tuple[float, float] | None = None) -> Objects:
        return refine_mask(seeds, image.to(depth.dtype), depth, self.params, focal=focal)


BUILTIN: dict[str, Callable[[DetectionParams], Segmenter]] = {"grow": RegionGrower}


def available_segmenters() -> list[str]:
    """Names of the built-in and installed segmenters, sorted."""
    return sorted(set(BUILTIN) | {ep.name for ep in entry_points(group=ENTRY_POINT_GROUP)})


def get_segmenter(name: str, params: DetectionParams | None = None) -> Segmenter:
    """The segmenter called ``name`` (built-ins first, then plugins); UserError if unknown or broken."""
    params = params or DetectionParams()
    factory = BUILTIN.get(name)
    if factory is None:
        eps = {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}
        if name not in eps:
            raise UserError(f"unknown segmenter '{name}' (known: {', '.join(available_segmenters())})")
        try:
            factory = eps[name].load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin is reported, not raised raw
            raise UserError(f"segmenter plugin '{name}' ({eps[name].value}) failed to load: {exc}") from None
    seg = factory(params)
    if not isinstance(seg, Segmenter):
        raise UserError(f"segmenter plugin '{name}' returned {type(seg).__name__}, which has no segment() method")
    return seg
