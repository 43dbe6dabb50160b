"""Frame sources on the real clips in ../shared/data (skipped when absent)."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.io.input import open_source
from droidw_cli.io.prepare import FramePreparer


def test_vtest_avi(shared_data):
    src = open_source(shared_data / "real" / "vtest" / "vtest.avi")
    assert len(src) == 795 and src.size == (576, 768) and src.fps == pytest.approx(10.0)
    count, last = 0, None
    for frame in src:
        count, last = count + 1, frame
    assert count == 795 and last.index == 794 and last.timestamp == pytest.approx(79.4)
    assert last.image.shape == (576, 768, 3)


def test_lady_running_folder_and_mp4_agree(shared_data):
    folder = open_source(shared_data / "real" / "lady-running")
    video = open_source(shared_data / "real" / "lady-running.mp4")
    for src in (folder, video):
        assert len(src) == 65 and src.size == (480, 854) and src.name == "lady-running"
    pairs = list(zip(open_source(shared_data / "real" / "lady-running", stride=16), open_source(
        shared_data / "real" / "lady-running.mp4", stride=16)))
    assert len(pairs) == 5
    for a, b in pairs:
        assert a.timestamp == pytest.approx(b.timestamp)
        assert np.abs(a.image.astype(np.float32) - b.image).mean() < 8  # same clip, different compression
    prep = FramePreparer(folder.size, None)
    assert prep.image(pairs[0][0].image).shape == prep.size + (3,)


def test_bedroom_folder(shared_data):
    src = open_source(shared_data / "real" / "bedroom", fps=24.0)
    assert len(src) == 200 and src.size == (540, 960) and src.intrinsics_hint is None
    frames = list(open_source(shared_data / "real" / "bedroom", fps=24.0, start=190))
    assert [f.index for f in frames] == list(range(10))
    assert frames[-1].timestamp == pytest.approx(199 / 24.0)
