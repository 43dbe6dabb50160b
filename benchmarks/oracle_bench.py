#!/usr/bin/env python3
"""Where a trajectory's error comes from: the tracker with parts of its correspondences made exact.

    python benchmarks/oracle_bench.py [--presets forward] [--seeds 2 3] [--static]
                                      [--modes dis exact-start exact-flow exact-model] [--set KEY=VALUE ...]

Each keyframe edge's correspondence is made one of four ways, everything else (confidence, masks,
uncertainty, BA, the filler's own flows) as in ``droidw track``:

* ``dis``: the tracker as it is (DIS started from the flow the current poses and depths induce);
* ``exact-start``: DIS started from the flow the *true* poses and depth induce, so only DIS's own
  error is left (the tracker's starts carry its current error, and DIS keeps part of a start's error);
* ``exact-flow``: the true induced flow of every pixel instead of DIS's, brought to the 1/8 grid as the
  tracker does (the block mean, :func:`~droidw_cli.correspondence.grid.flow_to_target`): what a perfect
  flow would give;
* ``exact-mask``: DIS as the tracker runs it, every grid cell of frame i that covers a mover's pixel (the
  generator's mask) weighted zero: what a perfect dynamic mask would give;
* ``exact-model``: the target of each grid cell is where the cell centre at the cell's mean inverse
  depth lands, exactly the BA's model (Eq. 1 on the grid): the control, whose error is the
  optimisation's alone.

The gap between ``exact-flow`` and ``exact-model`` is the error of the grid target itself: the mean of a
block's correspondences is not the correspondence of the block's centre where the flow is not affine in
the image (perspective, slanted surfaces); the gap between ``dis`` and ``exact-start`` is the start's.
Sequences come from ``benchmarks/.cache`` as in ``track_bench.py`` (``--static``: the same path with no
movers).  The oracles know a frame by a hash of its working-size grey image; an edge whose image they
do not know (the global BA's, matched from JPEG-stored images) stays DIS's, and the table counts the
oracle's calls that knew both frames and those that did not (none in ``dis`` mode, which never asks).
Columns: ATE over every frame and over keyframes (Sim(3)), ATE over the true path length, and the scale
drift: the aligned estimate's step length over the true one, in the first and in the last third.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, print_table, run_case_subprocess  # noqa: E402
from flow_bench import _listed, induced_flow  # noqa: E402

MODES = ("dis", "exact-start", "exact-flow", "exact-model", "exact-mask")


class GroundTruth:
    """The true poses (camera-to-world) and working-size depths of a cached sequence, frames known by hash."""

    def __init__(self, folder: Path, preparer, depth_scale: float):
        import cv2

        from droidw_cli.correspondence.dis import to_gray
        from droidw_cli.io.trajectory import read_tum

        self.folder, self.prep, self.depth_scale = folder, preparer, depth_scale
        self.poses = read_tum(folder / "groundtruth.txt").poses
        self.rgb, self.depths = _listed(folder / "rgb.txt"), _listed(folder / "depth.txt")
        self.masks = _listed(folder / "mask.txt") if (folder / "mask.txt").exists() else []
        self.index = {}
        for n, name in enumerate(self.rgb):
            image = preparer.image(cv2.cvtColor(cv2.imread(str(folder / name)), cv2.COLOR_BGR2RGB))
            self.index[self.key(to_gray(image))] = n
        self._depth: dict[int, np.ndarray] = {}

    @staticmethod
    def key(gray: np.ndarray) -> str:
        return hashlib.blake2b(np.ascontiguousarray(gray).tobytes(), digest_size=16).hexdigest()

    def frame(self, gray: np.ndarray) -> int | None:
        return self.index.get(self.key(gray))

    def depth(self, n: int) -> np.ndarray:
        import cv2

        if n not in self._depth:
            raw = cv2.imread(str(self.folder / self.depths[n]), cv2.IMREAD_UNCHANGED).astype(np.float32)
            self._depth[n] = self.prep.depth(raw / self.depth_scale)
        return self._depth[n]

    def mover_cells(self, n: int, grid: tuple[int, int]) -> np.ndarray:
        """(h, w) bool: the 1/8-grid cells of frame n with any mover pixel (none without masks)."""
        import cv2

        if not self.masks:
            return np.zeros(grid, bool)
        raw = cv2.imread(str(self.folder / self.masks[n]), cv2.IMREAD_UNCHANGED)
        small = self.prep.depth((raw > 0).astype(np.float32))  # nearest neighbour to the working size
        h, w = grid
        return small[: h * 8, : w * 8].reshape(h, 8, w, 8).max(axis=(1, 3)) > 0

    def relative(self, a: int, b: int) -> np.ndarray:
        """The 4×4 motion from camera a to camera b."""
        return np.linalg.inv(self.poses[b]) @ self.poses[a]

    def pixel_flow(self, a: int, b: int) -> np.ndarray:
        """The true induced flow a → b of every working-size pixel (:func:`flow_bench.induced_flow`)."""
        return induced_flow(self.depth(a), self.prep.intrinsics, self.relative(a, b))

    def model_flow(self, a: int, b: int) -> np.ndarray:
        """The BA model's flow a → b (:func:`model_flow`)."""
        return model_flow(self.depth(a), self.prep.intrinsics, self.relative(a, b))


def model_flow(depth: np.ndarray, intrinsics: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """A working-size flow (H, W, 2) float32 whose block means are the BA model's targets: each 8×8 block
    moves as its cell centre g at the block's mean inverse depth d̄(g) does, p*(g) = π(rel · π⁻¹(g, d̄(g)))
    with the grid intrinsics (``depth`` (H, W) metres, 0 = none; ``rel`` the 4×4 motion i → j)."""
    from droidw_cli.correspondence.grid import BLOCK, area_downsample
    from droidw_cli.geometry.camera import BA_SCALE, scale_intrinsics

    inv = area_downsample(np.where(depth > 0, 1.0 / np.maximum(depth, 1e-6), 0.0).astype(np.float32))
    k_grid = scale_intrinsics(np.asarray(intrinsics, dtype=np.float64), BA_SCALE)
    grid_flow = induced_flow(1.0 / np.maximum(inv, 1e-9), k_grid, rel) * BLOCK
    return np.repeat(np.repeat(grid_flow, BLOCK, 0), BLOCK, 1).astype(np.float32)


def oracle_source(mode: str, truth: GroundTruth, cfg):
    """A DIS correspondence source whose keyframe edges are made as ``mode`` says (module docstring)."""
    import torch

    from droidw_cli.correspondence.base import MatchCall
    from droidw_cli.correspondence.dis import DISCorrespondence, to_gray

    class Oracle(DISCorrespondence):
        known = unknown = 0

        def _pair(self, gray_i, gray_j):
            a, b = truth.frame(gray_i), truth.frame(gray_j)
            if a is None or b is None:
                Oracle.unknown += 1
                return None
            Oracle.known += 1
            return a, b

        def stages(self, call):
            if mode == "exact-start":
                pair = self._pair(to_gray(call.image_i), to_gray(call.image_j))
                if pair is not None:
                    call = MatchCall(call.image_i, call.image_j, truth.pixel_flow(*pair), call.both)
            return super().stages(call)

        def _scored(self, gray_i, gray_j, fwd, bwd):
            if mode in ("exact-flow", "exact-model"):
                pair = self._pair(gray_i, gray_j)
                if pair is not None:
                    make = truth.pixel_flow if mode == "exact-flow" else truth.model_flow
                    fwd, bwd = make(*pair), make(*pair[::-1])
            out = super()._scored(gray_i, gray_j, fwd, bwd)
            if mode == "exact-mask":
                pair = self._pair(gray_i, gray_j)
                if pair is not None:
                    movers = torch.from_numpy(truth.mover_cells(pair[0], tuple(out.weight.shape[:2])))
                    out.weight[movers] = 0.0
            return out

    return Oracle(cfg)


def _aligned(gt: np.ndarray, est: np.ndarray) -> np.ndarray:
    """est (N, 3) after the Sim(3) alignment onto gt (Umeyama)."""
    from droidw_cli.eval.align import umeyama

    return umeyama(est, gt).apply_points(est)


def _scale_drift(gt: np.ndarray, est: np.ndarray) -> tuple[float, float]:
    """Aligned step length over the true one, in the first and the last third of the path."""
    n = len(gt)
    out = []
    for lo, hi in ((0, n // 3), (n - n // 3 - 1, n - 1)):
        out.append(float(np.linalg.norm(est[hi] - est[lo]) / max(np.linalg.norm(gt[hi] - gt[lo]), 1e-12)))
    return out[0], out[1]


def one(args: argparse.Namespace) -> None:
    """Track one sequence with one mode and print a JSON line (internal: called in a subprocess)."""
    import time

    from droidw_cli.ba.registry import get_backend
    from droidw_cli.config import load_config
    from droidw_cli.features import get_feature_extractor
    from droidw_cli.io.calibration import Calibration
    from droidw_cli.io.input import open_source
    from droidw_cli.io.prepare import FramePreparer
    from droidw_cli.slam.tracker import Tracker
    from droidw_cli.synth import SynthConfig

    synth = SynthConfig.preset(args.preset, seed=args.seed, static=args.static)
    folder = cached_sequence(synth, args.preset + ("-static" if args.static else ""))
    cfg = load_config("default", list(args.set))
    source = open_source(folder)
    first = next(iter(source))
    prep = FramePreparer(first.image.shape[:2], np.asarray(synth.intrinsics, dtype=np.float64), cfg.io.target_area)
    truth = GroundTruth(folder, prep, synth.depth_scale)
    corr = oracle_source(args.mode, truth, cfg.correspondence)
    features = get_feature_extractor(cfg.features.name) if cfg.uncertainty.enable else None
    tracker = Tracker(cfg, get_backend(args.backend), corr, features, progress=False)
    t0 = time.perf_counter()
    result = tracker.run(source, Calibration(*(float(v) for v in synth.intrinsics)))
    seconds = time.perf_counter() - t0
    gt = truth.poses[:, :3, 3]
    est = _aligned(gt, result.poses_c2w[:, :3, 3])
    kf = result.kf_index
    est_kf = _aligned(gt[kf], result.poses_c2w[kf, :3, 3])
    path = float(np.linalg.norm(np.diff(gt, axis=0), axis=1).sum())
    print(json.dumps({"ate_cm": 100 * float(np.sqrt(((est - gt) ** 2).sum(1).mean())),
                      "ate_kf_cm": 100 * float(np.sqrt(((est_kf - gt[kf]) ** 2).sum(1).mean())),
                      "path_m": path, "drift": _scale_drift(gt, est), "keyframes": int(len(kf)),
                      "known": type(corr).known, "unknown": type(corr).unknown, "seconds": seconds}))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", nargs="+", default=["forward"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[2, 3])
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    ap.add_argument("--static", action="store_true", help="the same paths with no movers")
    ap.add_argument("--backend", default="native")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--preset", default="forward", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--mode", default="dis", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        one(args)
        return
    rows = []
    for preset in args.presets:
        for seed in args.seeds:
            for mode in args.modes:
                case = ["--preset", preset, "--seed", str(seed), "--mode", mode, "--backend", args.backend]
                case += (["--static"] if args.static else []) + [x for s in args.set for x in ("--set", s)]
                r = run_case_subprocess("oracle_bench.py", case)
                first, last = r["drift"]
                rows.append([f"{preset}{' static' if args.static else ''} seed {seed}", mode, f"{r['ate_cm']:.2f}",
                             f"{r['ate_kf_cm']:.2f}", f"{r['ate_cm'] / r['path_m']:.3f}",
                             f"{first:.4f} / {last:.4f}", r["keyframes"], f"{r['known']} / {r['unknown']}"])
    print("\nThe tracker with exact parts (default config, known calibration; drift: aligned step length over the "
          "true one, first / last third)")
    print_table(["sequence", "correspondence", "ATE [cm]", "ATE kf [cm]", "ATE [% path]", "scale first / last",
                 "keyframes", "calls known / not"], rows)


if __name__ == "__main__":
    main()
