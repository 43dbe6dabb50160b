"""XFeat on real footage: vtest.avi has a fixed camera, so static cells keep their features."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.correspondence import DISCorrespondence, grid_coordinates
from droidw_cli.features import get_feature_extractor

from video_frames import read_frames

pytestmark = pytest.mark.shared


def test_static_cells_are_similar_and_moving_people_are_not(shared_data):
    f0, f30 = read_frames(shared_data / "real" / "vtest" / "vtest.avi", [0, 30])
    feats = get_feature_extractor("xfeat").extract(torch.from_numpy(np.stack([f0, f30])).permute(0, 3, 1, 2))
    cos = (feats[0] * feats[1]).sum(0).numpy()
    corr = DISCorrespondence().match(f0, f30)
    moved_px = 8 * np.linalg.norm(corr.target.numpy() - grid_coordinates(36, 48), axis=-1)
    static, moving = moved_px < 0.3, moved_px > 2.0
    assert static.sum() > 500 and moving.sum() > 20
    assert np.median(cos[static]) > 0.95
    assert np.median(cos[moving]) < np.median(cos[static]) - 0.1
