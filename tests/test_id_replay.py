"""benchmarks/id_replay.py: the tracker overrides it accepts."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
_spec = importlib.util.spec_from_file_location("id_replay", _BENCH / "id_replay.py")
replay = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(replay)


def test_overrides_take_the_type_of_the_tracker_field():
    out = replay.parse_overrides(["depth_tol=0.35", "max_missed=3", "split_blur=1"])
    assert out == {"depth_tol": 0.35, "max_missed": 3, "split_blur": 1}
    assert isinstance(out["max_missed"], int) and isinstance(out["depth_tol"], float)


@pytest.mark.parametrize("item", ["bogus=1", "frame=2", "active=1", "depth_tol", "_next_id=4"])
def test_unknown_fields_and_tracking_state_are_refused(item):
    with pytest.raises(SystemExit, match="expected FIELD=VALUE"):
        replay.parse_overrides([item])
