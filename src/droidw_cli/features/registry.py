"""Find a feature extractor by name: built-ins, then the ``droidw.features`` entry points.

A plugin package declares, in its ``pyproject.toml``::

    [project.entry-points."droidw.features"]
    myfeat = "mypkg.feat:MyExtractor"

The entry point must load a callable (usually a :class:`FeatureExtractor`
subclass) that accepts ``device=`` and returns a :class:`FeatureExtractor`.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Callable

import torch

from droidw_cli.errors import UserError
from droidw_cli.features.base import FeatureExtractor

ENTRY_POINT_GROUP = "droidw.features"


def _make_xfeat(device: torch.device | str = "cpu") -> FeatureExtractor:
    from droidw_cli.features.xfeat import XFeatExtractor

    return XFeatExtractor(device=device)


BUILTIN: dict[str, Callable[..., FeatureExtractor]] = {"xfeat": _make_xfeat}


def _plugins() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available_feature_extractors() -> list[str]:
    """Names of the built-in and installed feature extractors, sorted."""
    return sorted(set(BUILTIN) | set(_plugins()))


def get_feature_extractor(name: str, device: torch.device | str = "cpu") -> FeatureExtractor:
    """The feature extractor called ``name`` running on ``device``.

    Built-in names win over plugins of the same name.  Raises UserError for
    an unknown name (listing the known ones) or a plugin that fails to load.
    """
    factory = BUILTIN.get(name)
    if factory is None:
        ep = _plugins().get(name)
        if ep is None:
            raise UserError(f"unknown feature extractor '{name}' (known: {', '.join(available_feature_extractors())})")
        try:
            factory = ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin is reported, not raised raw
            raise UserError(f"feature extractor plugin '{name}' ({ep.value}) failed to load: {exc}") from None
    extractor = factory(device=device)
    if not isinstance(extractor, FeatureExtractor):
        raise UserError(f"feature extractor plugin '{name}' returned {type(extractor).__name__}, not a FeatureExtractor")
    return extractor
