"""Cameras travelling into the scene, end to end at a small size: a forward walk and a KITTI-like drive.

The full-size figures (450-frame walk, 240-frame ride, 100-frame drive at
1241 × 376, three seeds each) come from ``benchmarks/track_bench.py``; these
clips hold the heading of the first keyframes and bound the drift, so that a
regression (a flat start that takes the walk for a sideways motion, a
keyframe gap that the flow cannot bridge at 10 frames/s) shows in
``make test``.  Bounds: CLIPS below, from the figures measured when written (in
its comment) with margin.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from cli_run import run
from droidw_cli.eval import evaluate_ate
from droidw_cli.eval.metrics import heading_error
from droidw_cli.io.trajectory import read_kitti, read_trajectory
from droidw_cli.synth import SynthConfig, write_sequence
from droidw_cli.synth.config import KITTI_CAMERA

HALF_KITTI = {"width": 620, "height": 188, "fx": KITTI_CAMERA["fx"] / 2, "fy": KITTI_CAMERA["fy"] / 2,
              "cx": (KITTI_CAMERA["cx"] + 0.5) / 2 - 0.5, "cy": (KITTI_CAMERA["cy"] + 0.5) / 2 - 0.5}
#: (clip, ATE bound in % of the path, heading bound in degrees).  Measured when written: the walk (7.3 m at
#: 320 × 240, tracked at 76 800 px) 0.92 cm = 0.125 %, heading 0.26°; the drive (46.7 m at 620 × 188) 3.0 cm
#: = 0.065 %, heading 0.21°; with keyframe placement (slam/placement.py) 0.82 cm = 0.112 % and 1.08 cm = 0.023 %,
#: headings 0.09° and 0.10°.  Before the forward-motion work the 450-frame walk drifted 246 cm (1.2 %) with a
#: heading 43° off.
CLIPS = {
    "forward": (SynthConfig.preset("forward", width=320, height=240, frames=150, seed=4), 0.4, 2.0),
    "drive": (SynthConfig.preset("drive", **HALF_KITTI, frames=40, seed=4, grey=True, texel_density=60.0), 0.3, 2.0),
}


def _track(seq, out, capsys, sets):
    code, _, err = run(["track", str(seq), "--out", str(out), "--quiet", *sets], capsys)
    assert code == 0, err
    return out


@pytest.fixture(scope="module", params=sorted(CLIPS))
def clip(request, tmp_path_factory):
    name = request.param
    cfg = CLIPS[name][0]
    layout = "kitti" if name == "drive" else "tum"  # the drive as KITTI odometry writes it: no --calib needed
    seq = write_sequence(cfg, tmp_path_factory.mktemp(name) / "seq", progress=False, layout=layout)
    return name, cfg, seq


def test_the_walk_and_the_drive_keep_their_heading_and_scale(clip, tmp_path, capsys):
    name, cfg, seq = clip
    out = _track(seq, tmp_path / "run", capsys, [] if name == "drive" else ["--set", "io.target_area=76800"])
    est = read_trajectory(out / "traj.txt")
    if name == "drive":
        gt = read_kitti(seq / "poses.txt").poses
        times = np.loadtxt(seq / "times.txt")
        np.testing.assert_allclose(est.timestamps, times, atol=1e-6)  # the folder's own timestamps
        calib = json.loads((out / "run.json").read_text())["calibration"]
        assert calib["source"] == "input"
        gt_traj = type(est)(times, gt)
    else:
        gt_traj = read_trajectory(seq / "groundtruth.txt")
        gt = gt_traj.poses
    path = float(np.linalg.norm(np.diff(gt[:, :3, 3], axis=0), axis=1).sum())
    ate = evaluate_ate(gt_traj, est).rmse
    with np.load(out / "keyframes.npz") as z:
        first = z["index"][:5]
    heading = heading_error(gt[first], est.poses[first])
    _, ate_bound, heading_bound = CLIPS[name]
    print(f"{name}: heading {heading:.2f}°, ATE {100 * ate:.2f} cm = {100 * ate / path:.3f} % of {path:.1f} m")
    assert heading < heading_bound, f"{name}: initial heading {heading:.1f}°"
    assert 100 * ate / path < ate_bound, f"{name}: ATE {100 * ate:.2f} cm = {100 * ate / path:.3f} % of {path:.1f} m"
