"""Entry points for the plugin-registry tests, without installing a package."""

from __future__ import annotations


class FakeEntryPoint:
    """Stands in for an ``importlib.metadata`` entry point; ``obj`` an exception makes ``load`` raise it."""

    def __init__(self, name, obj, value="fake.module:obj"):
        self.name, self.value, self._obj = name, value, obj

    def load(self):
        if isinstance(self._obj, Exception):
            raise self._obj
        return self._obj


def plug_entry_points(monkeypatch, registry, *eps) -> None:
    """Make ``registry`` (a module with ``entry_points`` and ``ENTRY_POINT_GROUP``) see only ``eps``."""
    monkeypatch.setattr(registry, "entry_points",
                        lambda group: [ep for ep in eps if group == registry.ENTRY_POINT_GROUP])
