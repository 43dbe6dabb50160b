"""Wall time per pipeline stage, and proxies that time an object's methods."""

from __future__ import annotations

import time
from collections import defaultdict
from contextlib import contextmanager


class StageTimer:
    """Accumulates seconds per named stage."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = defaultdict(float)

    @contextmanager
    def __call__(self, stage: str):
        t = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[stage] += time.perf_counter() - t

    def as_dict(self) -> dict[str, float]:
        return {k: round(v, 4) for k, v in self.seconds.items()}


class Timed:
    """Wraps an object so that calls to the named methods count toward ``stage``."""

    def __init__(self, inner, timer: StageTimer, stage: str, methods: tuple[str, ...]):
        self._inner, self._timer, self._stage, self._methods = inner, timer, stage, methods

    def __getattr__(self, name: str):
        attr = getattr(self._inner, name)
        if name not in self._methods:
            return attr

        def timed(*args, **kwargs):
            with self._timer(self._stage):
                return attr(*args, **kwargs)

        return timed
