"""DIS on real footage: vtest.avi has a fixed camera and walking pedestrians."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.correspondence import DISCorrespondence, grid_coordinates

from video_frames import read_frames

pytestmark = pytest.mark.shared


def test_fixed_camera_gives_zero_flow_with_high_confidence_on_the_background(shared_data):
    f0, f10 = read_frames(shared_data / "real" / "vtest" / "vtest.avi", [0, 10])
    dis = DISCorrespondence()
    corr = dis.match(f0, f10)
    moved_px = 8 * np.linalg.norm(corr.target.numpy() - grid_coordinates(36, 48), axis=-1)
    weight = corr.weight[..., 0].numpy()
    assert np.median(np.linalg.norm(corr.flow, axis=-1)) < 0.2
    assert weight[moved_px < 0.3].mean() > 0.9  # the static background is trusted
    assert weight[moved_px > 2.0].mean() < 0.5  # pedestrians (and their occlusions) mostly are not
    assert (moved_px > 2.0).mean() < 0.2
    assert dis.mean_flow(f0, f10) < 2.0  # below the motion filter's 3 px
