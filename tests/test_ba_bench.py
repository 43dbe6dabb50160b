"""benchmarks/ba_bench.py runs its ``--window`` measurement (a real ``run_window`` on a keyframe buffer)."""

from __future__ import annotations

import math

from bench_scripts import load

bench = load("ba_bench")


def test_window_measurement_runs_the_tracker_window():
    row = bench.measure("cpu", 6, None, (12, 16), reps=1, threads=None, with_window=True)
    assert row["keyframes"] == 6 and row["edges"] > 0
    for key in ("ms_ba_step", "ms_uncertainty_step", "ms_window_iter"):
        assert math.isfinite(row[key]) and row[key] > 0.0, key
