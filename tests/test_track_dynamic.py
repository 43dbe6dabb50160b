"""Dynamic uncertainty end to end on a short synthetic sequence with movers.

The full-size acceptance figures (300 frames, 3 dynamic seeds and a static
control) come from ``benchmarks/dynamic_bench.py``; this test keeps the same
measures on a short clip so that a regression shows up in ``make test``.
"""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.cli import main
from droidw_cli.eval import evaluate_ate
from droidw_cli.eval.dynamic import auroc, masks_on_grid
from droidw_cli.export.pointcloud import CloudParams, build_cloud
from droidw_cli.io.trajectory import read_trajectory
from droidw_cli.synth import SynthConfig, write_sequence

AREA = 76800  # 240 x 320 working size


def _run(seq, out, *sets):
    args = ["track", str(seq), "--out", str(out), "--quiet", "--set", f"io.target_area={AREA}"]
    for s in sets:
        args += ["--set", s]
    try:
        main(args)
    except SystemExit as exc:
        assert exc.code in (0, None)
    return out


@pytest.fixture(scope="module")
def dynamic_runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("dyn")
    cfg = SynthConfig.preset("dynamic", width=320, height=240, frames=80, seed=1, camera_speed=1.5)
    seq = write_sequence(cfg, root / "seq", progress=False)
    on = _run(seq, root / "on")
    off = _run(seq, root / "off", "uncertainty.enable=false")
    return seq, on, off


def test_uncertainty_beats_the_unweighted_baseline(dynamic_runs):
    seq, on, off = dynamic_runs
    gt = read_trajectory(seq / "groundtruth.txt")
    ate_on = evaluate_ate(gt, read_trajectory(on / "traj.txt")).rmse
    ate_off = evaluate_ate(gt, read_trajectory(off / "traj.txt")).rmse
    assert ate_on < ate_off, f"uncertainty on {ate_on * 100:.2f} cm vs off {ate_off * 100:.2f} cm"


def test_uncertainty_ranks_movers_above_the_background(dynamic_runs):
    seq, on, _ = dynamic_runs
    with np.load(on / "keyframes.npz") as z:
        unc, index = z["uncertainty"], z["index"]
    masks = masks_on_grid([seq / "mask" / f"{name}" for name in _mask_names(seq, index)], (240, 320), AREA)
    score = auroc(unc, masks)
    assert score > 0.75, f"AUROC {score:.3f}"


def test_static_cloud_is_mostly_static(dynamic_runs):
    seq, on, _ = dynamic_runs
    with np.load(on / "keyframes.npz") as z:
        npz = {k: z[k] for k in z.files}
    masks = masks_on_grid([seq / "mask" / n for n in _mask_names(seq, npz["index"])], (240, 320), AREA)
    cloud = build_cloud(npz, CloudParams())
    dynamic_share = (cloud.static & masks.reshape(-1)).sum() / max(1, cloud.static.sum())
    everything_share = masks.mean()
    assert cloud.static.sum() > 1000
    assert dynamic_share < 0.5 * everything_share, (dynamic_share, everything_share)


def _mask_names(seq, index):
    names = sorted(p.name for p in (seq / "mask").iterdir())
    return [names[int(k)] for k in index]
