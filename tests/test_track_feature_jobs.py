"""Keyframe features computed on the worker thread are all read at the end of a run, however late they come.

The tracker extracts each keyframe's features on a one-thread pool.  A run that ended while jobs were still
queued used to cancel them on shutdown and then fail reading the keyframes' uncertainty (CancelledError; seen
in the demo test on a loaded machine).  A deliberately slow extractor makes the jobs queue every time.
"""

from __future__ import annotations

import time

import numpy as np
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.correspondence import get_correspondence_source
from droidw_cli.features.base import FeatureExtractor
from droidw_cli.io.calibration import load_calibration
from droidw_cli.io.input import open_source
from droidw_cli.slam.tracker import Tracker
from droidw_cli.synth import SynthConfig, write_sequence


class SlowFeatures(FeatureExtractor):
    """Unit-norm descriptors from the image's colours at 1/8 size, 0.3 s a call."""

    name, channels, stride = "slow", 3, 8

    def extract(self, images: torch.Tensor) -> torch.Tensor:
        time.sleep(0.3)
        x = torch.nn.functional.avg_pool2d(images.float(), self.stride) + 1e-3
        return x / x.norm(dim=1, keepdim=True)


def test_queued_feature_jobs_finish_and_are_read(tmp_path):
    seq = write_sequence(SynthConfig.preset("dynamic", width=320, height=240, frames=8, seed=1,
                                                             camera_speed=2.5), tmp_path / "seq",
                         progress=False)
    # no prefetch thread: every keyframe's features go through the pool; a run that never initialises reads
    # none of them before the end, so most are still queued when the frames run out
    cfg = load_config("default", ["io.target_area=76800", "io.prefetch=0", "motion_filter.thresh=0.5",
                                 "frontend.warmup=50", "frontend.init_parallax=1000"])
    source = open_source(seq)
    result = Tracker(cfg, get_backend("cpu"), get_correspondence_source(cfg.correspondence), SlowFeatures(),
                     progress=False).run(source, load_calibration(seq / "calib.txt"))
    assert len(result.timestamps) == 8 and not result.initialised
    assert result.kf_features is not None and len(result.kf_features) == len(result.kf_index) >= 2
    assert np.isfinite(result.kf_uncertainty).all()

