"""benchmarks/id_replay.py: the tracker overrides it accepts."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from bench_scripts import load

replay = load("id_replay")


def test_overrides_take_the_type_of_the_tracker_field():
    out = replay.parse_overrides(["depth_tol=0.35", "max_missed=3", "split_blur=1"])
    assert out == {"depth_tol": 0.35, "max_missed": 3, "split_blur": 1}
    assert isinstance(out["max_missed"], int) and isinstance(out["depth_tol"], float)


@pytest.mark.parametrize("item", ["bogus=1", "frame=2", "active=1", "depth_tol", "_next_id=4"])
def test_unknown_fields_and_tracking_state_are_refused(item):
    with pytest.raises(SystemExit, match="expected FIELD=VALUE"):
        replay.parse_overrides([item])


def _capture(disparity: torch.Tensor, sensor_depth: bool) -> tuple[dict, np.ndarray]:
    """Two walkers side by side in one keyframe (columns 2-4 and 5-7), labelled as one object."""
    truth = np.zeros((2, 1, 8, 10), dtype=bool)
    truth[0, 0, 2:6, 2:5] = True
    truth[1, 0, 2:6, 5:8] = True
    ids = np.full((1, 8, 10), -1, dtype=np.int16)
    ids[0][truth[:, 0].any(0)] = 0
    return {"inputs": (None, None, disparity, None, None, sensor_depth), "truth": truth}, ids


def test_merged_counts_walkers_that_share_a_component_unless_a_depth_step_splits_it():
    near_far = torch.full((1, 8, 10), 0.5)
    near_far[0, :, 5:] = 0.25  # the second walker twice as far: a depth step between them
    capture, ids = _capture(near_far, sensor_depth=True)
    assert replay.merged_share(capture, ids) == 0.0
    capture, ids = _capture(near_far, sensor_depth=False)  # monocular: BA's depth is not used
    assert replay.merged_share(capture, ids) == 1.0
    capture, ids = _capture(torch.full((1, 8, 10), 0.5), sensor_depth=True)  # the same depth: one component
    assert replay.merged_share(capture, ids) == 1.0
    ids[0][:, 5:] = -1  # the second walker unlabelled: the first one's component holds nobody else
    assert replay.merged_share(capture, ids) == 0.0


@pytest.mark.parametrize("stem, preset, seed, apart", [("rotate-s3-rgbd", "rotate", 3, False),
                                                        ("walk-static-s2-mono", "walk-static", 2, False),
                                                        ("wobble-apart-s1-rgbd", "wobble", 1, True)])
def test_a_capture_name_gives_back_the_generator_config(stem, preset, seed, apart):
    from droidw_cli.synth import SynthConfig

    assert replay.capture_config(stem) == SynthConfig.preset(preset, seed=seed, apart=apart)
