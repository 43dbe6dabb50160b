"""A frame source that renders a synthetic sequence on the fly (nothing on disk).

Used by the memory benchmark, where minutes of video would not fit a
temporary folder comfortably; it is re-iterable like every other source.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from droidw_cli.io.calibration import Calibration
from droidw_cli.io.frames import Frame, FrameSource, Selection
from droidw_cli.synth.config import SynthConfig
from droidw_cli.synth.render import build_scene, render_sequence


class SynthSource(FrameSource):
    """Streams :class:`SynthConfig` frames (RGB and depth) with the generator's calibration."""

    def __init__(self, cfg: SynthConfig) -> None:
        super().__init__(Path(f"synth-seed{cfg.seed}"), Selection(), cfg.fps)
        self.cfg = cfg
        self.size = (cfg.height, cfg.width)
        self.intrinsics_hint = Calibration(*(float(v) for v in cfg.intrinsics))
        self._scene = build_scene(cfg)

    def __len__(self) -> int:
        return self.cfg.frames

    def __iter__(self) -> Iterator[Frame]:
        for f in render_sequence(self.cfg, scene=self._scene):
            yield Frame(f.index, f.timestamp, f.rgb, f.depth)
