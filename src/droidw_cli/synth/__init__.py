"""A synthetic dynamic-scene generator with exact ground truth.

A textured room with furniture, a moving camera (handheld, wobbling,
rotating, stop-and-go or fixed: :mod:`~droidw_cli.synth.motions`) and people
("walkers", textured boxes) walking through it; or a street with a camera
travelling down it (:mod:`~droidw_cli.synth.forward`) or following one walker
(:mod:`~droidw_cli.synth.follow`).  Per frame: colour, z-depth,
the mask of walker pixels and the camera pose — all exact, for tests,
benchmarks and ``droidw demo``.  The colour can get motion blur, gain drift,
noise and JPEG artefacts (:mod:`~droidw_cli.synth.photometric`); the ground
truth never does.

    >>> cfg = SynthConfig.preset("dynamic-small", seed=3)
    >>> for frame in render_sequence(cfg): ...        # streaming
    >>> write_sequence(cfg, "out/seq")                  # TUM-style folder
"""

from droidw_cli.synth.config import PRESETS, SynthConfig, SynthFrame
from droidw_cli.synth.render import build_scene, render_sequence
from droidw_cli.synth.scene import Scene
from droidw_cli.synth.writer import write_sequence

__all__ = ["PRESETS", "Scene", "SynthConfig", "SynthFrame", "build_scene", "render_sequence", "write_sequence"]
