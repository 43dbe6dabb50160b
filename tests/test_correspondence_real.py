"""DIS on real footage: vtest.avi has a fixed camera and walking pedestrians."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from droidw_cli.correspondence import DISCorrespondence, grid_coordinates

pytestmark = pytest.mark.shared


def read_frames(path, indices, size=(384, 288)):
    """RGB uint8 frames ``indices`` of a video, area-resized to ``size`` (w, h)."""
    cap = cv2.VideoCapture(str(path))
    frames, k = {}, 0
    while k <= max(indices):
        ok, frame = cap.read()
        assert ok, f"cannot read frame {k} of {path}"
        if k in indices:
            frames[k] = cv2.cvtColor(cv2.resize(frame, size, interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB)
        k += 1
    cap.release()
    return [frames[i] for i in indices]


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
