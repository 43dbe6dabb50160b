"""Frontend._window_start: the newest ``window`` keyframes, widened until the window reaches
``window_span`` input frames back, at most ``window_max`` keyframes."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from droidw_cli.config import FrontendConfig, load_config
from droidw_cli.errors import ConfigError
from droidw_cli.slam.frontend import Frontend, window_reach


def _start(frame_index: list[int], horizon: int = 200, **overrides) -> int:
    f = FrontendConfig(**overrides)
    fe = SimpleNamespace(fcfg=f, reach=window_reach(f, horizon), buffer=SimpleNamespace(frame_index=frame_index))
    return Frontend._window_start(fe, len(frame_index) - 1)


def test_slow_keyframes_keep_the_window_of_25():
    frames = [9 * n for n in range(60)]  # a keyframe every 9 frames: 25 of them span 216 frames
    assert _start(frames, window=25, window_span=180) == 60 - 25
    assert _start(frames, window=25, window_span=0) == 60 - 25


def test_fast_keyframes_widen_the_window_to_the_span_and_no_further_than_window_max():
    frames = [3 * n for n in range(80)]  # a keyframe every 3 frames: 25 of them span 72 frames
    assert _start(frames, window=25, window_span=90, window_max=35) == 79 - 30  # 30 keyframes reach 90 frames back
    assert _start(frames, window=25, window_span=180, window_max=35) == 80 - 35  # capped
    assert _start(frames, window=25, window_span=0, window_max=35) == 80 - 25  # off
    assert _start(frames[:20], window=25, window_span=180) == 0  # fewer keyframes than the window
    assert _start(frames, horizon=30, window=25, window_span=180, window_max=35) == 80 - 30  # inside the horizon


def test_window_span_is_validated_and_configured():
    with pytest.raises(ValueError, match="window_span"):
        FrontendConfig(window_span=-1)
    with pytest.raises(ConfigError, match="horizon"):
        load_config("default", ["frontend.window=12", "backend.horizon=10"])
    assert load_config("default").frontend.window_span == 180  # the monocular default
    assert load_config("fast").frontend.window_span == 0 and load_config("rgbd").frontend.window_span == 0
