"""--calib auto: the focal length is fixed while the keyframes cannot constrain it, and bounded.

On lady-running the focal length collapsed from 769 px to 5.8 px once the
parallax gate let initialisation start from 3 keyframes.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import CalibConfig, load_config
from droidw_cli.slam.focal import clamp_focal, focal_observable, rotation_span
from droidw_cli.slam.frontend import Frontend

from cli_run import run
from test_slam_backend import GRID, _NoMatch

K8 = torch.tensor([40.0, 40.0, 16.0, 12.0])


def _yaw(deg: float, t=(0.0, 0.0, 0.0)) -> torch.Tensor:
    half = math.radians(deg) / 2
    return torch.tensor([*t, 0.0, math.sin(half), 0.0, math.cos(half)])


def test_rotation_span_is_the_largest_pairwise_angle():
    poses = torch.stack([_yaw(-10.0), _yaw(5.0), _yaw(20.0, (1.0, 0.0, 0.0))])
    assert rotation_span(poses) == pytest.approx(30.0, abs=1e-6)
    assert rotation_span(poses[:1]) == 0.0


def test_the_focal_is_observable_only_with_enough_keyframes_and_rotation():
    cfg = CalibConfig(min_keyframes=4, min_rotation=5.0)
    sliding = torch.stack([_yaw(0.0, (0.1 * k, 0.0, 0.0)) for k in range(6)])  # translation only
    turning = torch.stack([_yaw(2.0 * k) for k in range(6)])  # 10 degrees
    assert not focal_observable(sliding, cfg)
    assert focal_observable(turning, cfg)
    assert not focal_observable(turning[:3], cfg)  # too few keyframes


def test_clamp_keeps_the_focal_within_its_bounds_of_the_guess():
    cfg = CalibConfig(focal_min=0.3, focal_max=3.0)
    k = torch.tensor([1.0, 500.0, 16.0, 12.0])
    out = clamp_focal(k, 40.0, cfg)
    assert out.tolist() == [12.0, 120.0, 16.0, 12.0]
    assert k[0] == 1.0  # not in place


def _sliding_frontend(n: int) -> Frontend:
    """--calib auto over n keyframes that only translate, with zero flow (which f → 0 explains best)."""
    cfg = load_config("default", ["uncertainty.enable=false", "dynamics.mode=none"])
    params = dataclasses.replace(cfg.ba, optimize_focal="shared")
    fe = Frontend(cfg, params, get_backend("cpu"), _NoMatch(), GRID, K8, 0)
    image = np.full((GRID[0] * 8, GRID[1] * 8, 3), 128, np.uint8)
    for k in range(n):
        fe.buffer.append(k, k / 10.0, _yaw(0.0, (0.05 * k, 0.0, 0.0)), 1.0 / 3.0, image[::8, ::8])
        fe.images[k] = image
    return fe


def test_initialisation_from_three_translating_keyframes_keeps_the_focal():
    fe = _sliding_frontend(3)
    fe._initialise()
    assert fe.initialised
    assert fe.shared.intrinsics[:2].tolist() == [40.0, 40.0]  # before the fix: 39.994 (f starts to shrink)


@pytest.mark.shared
def test_lady_running_focal_stays_plausible(shared_data, capsys, tmp_path):
    """854×480 hand-held clip of a runner: 5.81 px before the fix; any sane lens is 0.3-1.5 × width."""
    video = shared_data / "real" / "lady-running.mp4"
    if not video.exists():
        pytest.skip(f"{video} not available")
    code, _, err = run(["track", str(video), "--calib", "auto", "--backend", "cpu", "--quiet",
                        "--out", str(tmp_path)], capsys)
    assert code == 0, err
    fx = json.loads((tmp_path / "run.json").read_text())["calibration"]["fx"]
    assert 0.3 * 854 <= fx <= 1.5 * 854
