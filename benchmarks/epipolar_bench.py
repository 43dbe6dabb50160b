#!/usr/bin/env python3
"""Does the epipolar fit find the movers?  Mover cells flagged against static cells flagged, per fit.

    python benchmarks/epipolar_bench.py [--presets walk walk-static forward rotate] [--seed 1] [--gap 8]
                                        [--pairs 15] [--fits lmeds ransac0.3 droidw]

For ``pairs`` frame pairs (k, k + gap) of the generator's realistic sequences (rendered once into
``benchmarks/.cache``, as in ``track_bench.py``), the tracker's correspondence source matches the
pair at the working resolution (:class:`~droidw_cli.io.prepare.FramePreparer`; DIS MEDIUM with its
forward-backward and photometric confidence), and each fit of the fundamental matrix gives the
edge's Sampson distance map (:func:`droidw_cli.dynamics.epipolar.epipolar_distance`, the fit
swapped).  A cell is flagged where its distance exceeds the edge's threshold
max(``dynamics.epipolar_thresh``, 5 · median), undilated; the ground-truth masks of frame k,
area-reduced to the 1/8 grid, say which cells move.  Columns: the share of mover cells flagged
(recall; the BA must lose them), the share of static cells flagged (lost for nothing), the median
Sampson distance of the static cells over the pairs (the fit's precision, working px), and the
median milliseconds per fit on one thread.  Fits: ``lmeds`` (OpenCV's least median of squares,
droidw's fit before 2026-11-28), ``ransacT`` (OpenCV's 7-point RANSAC alone, inliers within T px),
``droidw`` (:func:`~droidw_cli.dynamics.epipolar.fit_fundamental`: RANSAC and 8-point refits).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, print_table  # noqa: E402


def fitter(name: str):
    """fit(x_i, x_j, inlier_px) → F or None for a fit's name (module docstring)."""
    import cv2

    from droidw_cli.dynamics.epipolar import fit_fundamental

    def opencv(method, threshold=None):
        def fit(x_i, x_j, inlier_px):
            args = (method,) if threshold is None else (method, threshold, 0.999)
            f, _ = cv2.findFundamentalMat(x_i, x_j, *args)
            return f if f is not None and f.shape == (3, 3) else None
        return fit
    if name == "lmeds":
        return opencv(cv2.FM_LMEDS)
    if name.startswith("ransac"):
        return opencv(cv2.FM_RANSAC, float(name[len("ransac"):]))
    if name == "droidw":
        return fit_fundamental
    raise SystemExit(f"epipolar_bench: unknown fit {name!r} (lmeds, ransacT, droidw)")


def measure(preset: str, seed: int, gap: int, pairs: int, fits: list[str]) -> list[list]:
    import cv2

    import droidw_cli.dynamics.epipolar as epipolar
    from droidw_cli.config import CorrespondenceConfig, DynamicsConfig
    from droidw_cli.correspondence.dis import DISCorrespondence
    from droidw_cli.correspondence.grid import area_downsample
    from droidw_cli.io.prepare import FramePreparer
    from droidw_cli.synth import SynthConfig

    cfg = SynthConfig.preset(preset, seed=seed)
    folder = cached_sequence(cfg, preset)

    def listed(kind: str) -> list[str]:
        text = (folder / f"{kind}.txt").read_text().splitlines()
        return [line.split()[1] for line in text if line.strip() and not line.startswith("#")]
    rgb, masks = listed("rgb"), listed("mask")

    def image(n: int) -> np.ndarray:
        return cv2.cvtColor(cv2.imread(str(folder / rgb[n])), cv2.COLOR_BGR2RGB)
    prep = FramePreparer(image(0).shape[:2], cfg.intrinsics)
    corr = DISCorrespondence(CorrespondenceConfig())
    thresh = DynamicsConfig().epipolar_thresh
    cv2.setNumThreads(1)
    counts = {f: np.zeros(4) for f in fits}
    static_dist: dict[str, list[float]] = {f: [] for f in fits}
    ms: dict[str, list[float]] = {f: [] for f in fits}
    original = epipolar.fit_fundamental
    for i in np.linspace(0, len(rgb) - gap - 1, pairs).astype(int):
        c = corr.match(prep.image(image(i)), prep.image(image(i + gap)))
        mask = prep.depth(cv2.imread(str(folder / masks[i]), cv2.IMREAD_GRAYSCALE).astype(np.float32)) > 0
        moving = area_downsample(mask.astype(np.float32)) >= 0.5
        for name in fits:
            fit = fitter(name)

            def timed(x_i, x_j, inlier_px, fit=fit, name=name):
                t0 = time.perf_counter()
                out = fit(x_i, x_j, inlier_px)
                ms[name].append(1000 * (time.perf_counter() - t0))
                return out
            epipolar.fit_fundamental = timed
            try:
                dist = epipolar.epipolar_distance(c.flow, c.weight[..., 0].numpy())
            finally:
                epipolar.fit_fundamental = original
            if dist is None:
                continue
            flagged = epipolar.moving_mask([dist], thresh, 0)
            counts[name] += [(flagged & moving).sum(), moving.sum(), (flagged & ~moving).sum(), (~moving).sum()]
            static_dist[name].append(float(np.median(dist[~moving])))
    rows = []
    for name in fits:
        n = counts[name]
        recall = f"{n[0] / n[1]:.3f}" if n[1] else "–"
        rows.append([f"{preset} seed {seed}", name, recall, f"{n[2] / max(n[3], 1):.4f}",
                     f"{np.median(static_dist[name]):.3f}", f"{np.median(ms[name]):.2f}"])
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", nargs="+", default=["walk", "walk-static", "forward", "rotate"])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--gap", type=int, default=8, help="frames between the pair's images")
    ap.add_argument("--pairs", type=int, default=15)
    ap.add_argument("--fits", nargs="+", default=["lmeds", "ransac0.3", "droidw"])
    args = ap.parse_args()
    rows = [row for p in args.presets for row in measure(p, args.seed, args.gap, args.pairs, args.fits)]
    print(f"\nEpipolar fits, {args.pairs} pairs {args.gap} frames apart per sequence, cells of the 1/8 grid")
    print_table(["sequence", "fit", "mover cells flagged", "static cells flagged", "static median dist [px]",
                 "ms per fit"], rows)


if __name__ == "__main__":
    main()
