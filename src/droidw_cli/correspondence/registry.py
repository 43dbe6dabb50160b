"""Find a correspondence source by name: built-ins, then the ``droidw.correspondence`` entry points.

A plugin package declares, in its ``pyproject.toml``::

    [project.entry-points."droidw.correspondence"]
    myflow = "mypkg.flow:MyCorrespondence"

The entry point must load a callable (usually a :class:`CorrespondenceSource`
subclass) that takes the :class:`~droidw_cli.config.CorrespondenceConfig` and
returns a :class:`CorrespondenceSource`.  ``cfg.name`` selects the source.
"""

from __future__ import annotations

from importlib.metadata import entry_points
from typing import Callable

from droidw_cli.config import CorrespondenceConfig
from droidw_cli.correspondence.base import CorrespondenceSource
from droidw_cli.correspondence.dis import DISCorrespondence
from droidw_cli.errors import UserError

ENTRY_POINT_GROUP = "droidw.correspondence"

BUILTIN: dict[str, Callable[[CorrespondenceConfig], CorrespondenceSource]] = {"dis": DISCorrespondence}


def _plugins() -> dict[str, object]:
    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available_correspondence_sources() -> list[str]:
    """Names of the built-in and installed correspondence sources, sorted."""
    return sorted(set(BUILTIN) | set(_plugins()))


def get_correspondence_source(cfg: CorrespondenceConfig | None = None) -> CorrespondenceSource:
    """The correspondence source named ``cfg.name``, built from ``cfg``.

    Built-in names win over plugins of the same name.  Raises UserError for
    an unknown name (listing the known ones) or a plugin that fails to load.
    """
    cfg = cfg or CorrespondenceConfig()
    factory = BUILTIN.get(cfg.name)
    if factory is None:
        ep = _plugins().get(cfg.name)
        if ep is None:
            raise UserError(
                f"unknown correspondence source '{cfg.name}' (known: {', '.join(available_correspondence_sources())})"
            )
        try:
            factory = ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plugin is reported, not raised raw
            raise UserError(f"correspondence plugin '{cfg.name}' ({ep.value}) failed to load: {exc}") from None
    source = factory(cfg)
    if not isinstance(source, CorrespondenceSource):
        raise UserError(f"correspondence plugin '{cfg.name}' returned {type(source).__name__}, not a CorrespondenceSource")
    return source
