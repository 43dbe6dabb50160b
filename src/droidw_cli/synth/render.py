"""Streaming rendering: frames are produced one at a time, so any length fits in memory."""

from __future__ import annotations

from collections.abc import Iterator

from droidw_cli.synth.config import SynthConfig, SynthFrame
from droidw_cli.synth.scene import Scene


def build_scene(cfg: SynthConfig) -> Scene:
    """Lay out the room, tune the walkers' paths and render the texture atlas (the costly set-up)."""
    return Scene(cfg)


def render_sequence(cfg: SynthConfig, start: int = 0, stop: int | None = None,
                    scene: Scene | None = None) -> Iterator[SynthFrame]:
    """Yield :class:`SynthFrame` for frames ``start … stop − 1`` (default: all ``cfg.frames``).

    Frames are rendered lazily; pass ``scene`` to reuse a built scene.
    """
    stop = cfg.frames if stop is None else stop
    if not 0 <= start <= stop <= cfg.frames:
        raise ValueError(f"need 0 <= start <= stop <= frames ({cfg.frames}), got {start}, {stop}")
    scene = build_scene(cfg) if scene is None else scene
    if scene.cfg != cfg:
        raise ValueError("scene was built for a different SynthConfig")
    for k in range(start, stop):
        yield scene.frame(k)
