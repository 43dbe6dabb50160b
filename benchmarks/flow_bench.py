#!/usr/bin/env python3
"""Is the correspondence source's parallax right?  Relative translation from its flow with exact depth.

    python benchmarks/flow_bench.py [--presets walk rotate] [--seed 1] [--gaps 4 8] [--pairs 12]
                                    [--flows gt medium fine fast] [--target-area 196608] [--coarsest-scale 0]

For frame pairs (k, k + gap) of the generator's realistic sequences (rendered
once into ``benchmarks/.cache``, as in ``track_bench.py``), each flow i → j is
brought to the BA's 1/8 grid exactly as the tracker does (working size by
:class:`~droidw_cli.io.prepare.FramePreparer`, block-mean targets
p*(g) = g + f̄/8, :func:`~droidw_cli.correspondence.grid.flow_to_target`).
With the ground-truth depth of frame i on the grid and its static cells
(no walker in the block, and every pixel's true correspondence inside frame j:
a pixel that leaves the view has no flow to measure, and where a start leads
out of the view the warped DIS keeps the start, so with ``--seeded`` those cells
read back whatever the start said), the motion-only problem

    min_T  Σ_g ρ(‖π(T · π⁻¹(g, D_i(g))) − p*(g)‖),   ρ Cauchy with σ = 1 grid px / 8,

is solved by Gauss-Newton (left perturbation of T ∈ SE(3), IRLS weights
1 / (1 + (r/σ)²)), started from the true relative pose, once over all six
degrees of freedom and once over the translation alone with the rotation held
at the truth.  The table gives, over the pairs, the median and 10/90 %
quantiles of ‖t‖ / ‖t_true‖ of the six-DoF solve (1 is right), the median of
the translation-only solve, and the six-DoF median rotation error.  The two
scales differ when the flow's errors are absorbed by the translation-rotation
ambiguity of a short baseline (a sideways translation and a yaw move near
points alike): the translation-only scale is the flow's own parallax bias, the
six-DoF scale what a two-view fit makes of it.  ``--seeded`` starts DIS from the flow the true pose
induces (the tracker starts its wide edges from the flow of its current
estimate).  ``gt`` is the flow induced by the true pose and
depth, a control that must read 1.  The other rows are DIS presets
(:data:`droidw_cli.correspondence.dis.PRESETS`; ``medium`` is the BA's
edges, ``fine`` the filler's), with their median milliseconds per flow on one
thread.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, print_table  # noqa: E402

SIGMA = 1.0 / 8  # the Cauchy scale: 1 working-resolution px, in grid px


def _exp_se3(xi: np.ndarray) -> np.ndarray:
    """4×4 of the small twist xi = (ω, v) (rotation by Rodrigues; the translation part applied as is)."""
    import cv2

    out = np.eye(4)
    out[:3, :3] = cv2.Rodrigues(xi[:3].reshape(3, 1))[0]
    out[:3, 3] = xi[3:]
    return out


def solve_motion(points: np.ndarray, target: np.ndarray, intrinsics: np.ndarray, start: np.ndarray,
                 iters: int = 15, translation_only: bool = False) -> np.ndarray:
    """The 4×4 T minimising the Cauchy-robust reprojection error of ``points`` (N, 3) onto ``target`` (N, 2).

    Projection π(X) = (fx X/Z + cx, fy Y/Z + cy); Gauss-Newton on T ← exp(ξ) T with
    ∂X'/∂ξ = [−[X']×, I] and ∂π/∂X' = [[fx/Z, 0, −fx X/Z²], [0, fy/Z, −fy Y/Z²]].
    ``translation_only``: ξ = (0, v), the rotation stays that of ``start``.
    """
    import torch

    from droidw_cli.geometry.lie import skew

    fx, fy, cx, cy = intrinsics
    pose = np.asarray(start, dtype=np.float64).copy()
    for _ in range(iters):
        x = points @ pose[:3, :3].T + pose[:3, 3]
        z = x[:, 2]
        r = np.stack([fx * x[:, 0] / z + cx, fy * x[:, 1] / z + cy], -1) - target
        jp = np.zeros((len(x), 2, 3))
        jp[:, 0, 0], jp[:, 0, 2] = fx / z, -fx * x[:, 0] / z**2
        jp[:, 1, 1], jp[:, 1, 2] = fy / z, -fy * x[:, 1] / z**2
        j = np.concatenate([jp @ -skew(torch.from_numpy(x)).numpy(), jp], axis=2).reshape(-1, 6)
        if translation_only:
            j = j[:, 3:]
        w = np.repeat(1.0 / (1.0 + (np.linalg.norm(r, axis=1) / SIGMA) ** 2), 2)
        step = np.linalg.solve(j.T @ (j * w[:, None]) + 1e-9 * np.eye(j.shape[1]), -j.T @ (w * r.ravel()))
        if translation_only:
            step = np.concatenate([np.zeros(3), step])
        pose = _exp_se3(step) @ pose
        if np.abs(step).max() < 1e-10:
            break
    return pose


def backproject(grid_depth: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """(h, w) depth on the grid → (h·w, 3) camera points of the cell centres g (grid coordinates)."""
    h, w = grid_depth.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    fx, fy, cx, cy = intrinsics
    d = grid_depth.astype(np.float64)
    return np.stack([(xs - cx) / fx * d, (ys - cy) / fy * d, d], -1).reshape(-1, 3)


def induced_flow(depth: np.ndarray, intrinsics: np.ndarray, rel: np.ndarray) -> np.ndarray:
    """Working-resolution flow (H, W, 2) float32 that the pose ``rel`` (i → j) induces on the depth of frame i."""
    h, w = depth.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    fx, fy, cx, cy = intrinsics
    d = np.where(depth > 0, depth, 1.0).astype(np.float64)
    x = np.stack([(xs - cx) / fx * d, (ys - cy) / fy * d, d], -1) @ rel[:3, :3].T + rel[:3, 3]
    z = np.maximum(x[..., 2], 1e-6)
    flow = np.stack([fx * x[..., 0] / z + cx - xs, fy * x[..., 1] / z + cy - ys], -1)
    return np.where((depth > 0)[..., None], flow, 0.0).astype(np.float32)


def _listed(index: Path) -> list[str]:
    """The file names of a TUM-style list (``timestamp filename`` lines after ``#`` comments)."""
    return [line.split()[1] for line in index.read_text().splitlines() if line.strip() and not line.startswith("#")]


def measure(preset: str, seed: int, gap: int, pairs: int, flows: list[str], target_area: int,
            seeded: bool = False, coarsest_scale: int = 0) -> list[list]:
    """One table row per flow: the translation's scale and the rotation error over ``pairs`` pairs."""
    import cv2

    from droidw_cli.correspondence.dis import calc_deep, dis_objects, to_gray
    from droidw_cli.correspondence.confidence import inside_mask
    from droidw_cli.correspondence.grid import area_downsample, flow_to_target
    from droidw_cli.geometry.camera import BA_SCALE, scale_intrinsics
    from droidw_cli.io.prepare import FramePreparer
    from droidw_cli.io.trajectory import read_tum

    from droidw_cli.synth import SynthConfig

    cfg = SynthConfig.preset(preset, seed=seed)
    folder = cached_sequence(cfg, preset)
    poses = read_tum(folder / "groundtruth.txt").poses
    files = {kind: _listed(folder / f"{kind}.txt") for kind in ("rgb", "depth", "mask")}
    n_frames = len(files["rgb"])

    def rgb(n: int) -> np.ndarray:
        return cv2.cvtColor(cv2.imread(str(folder / files["rgb"][n])), cv2.COLOR_BGR2RGB)

    prep = FramePreparer(rgb(0).shape[:2], cfg.intrinsics, target_area)
    k_work = prep.intrinsics
    k_grid = scale_intrinsics(k_work, BA_SCALE)
    starts = np.linspace(0, n_frames - gap - 1, pairs).astype(int)
    stats: dict[str, list[tuple[float, float, float, float]]] = {f: [] for f in flows}
    made: dict = {}  # the DIS objects, one per flow name and kind, as the tracker keeps them
    cv2.setNumThreads(1)
    for i in starts:
        j = i + gap
        rel = np.linalg.inv(poses[j]) @ poses[i]
        depth = prep.depth(cv2.imread(str(folder / files["depth"][i]), cv2.IMREAD_UNCHANGED).astype(np.float32) / cfg.depth_scale)
        moving = prep.depth(cv2.imread(str(folder / files["mask"][i]), cv2.IMREAD_GRAYSCALE).astype(np.float32)) > 0
        grid_depth = area_downsample(np.where(depth > 0, 1.0 / np.maximum(depth, 1e-6), 0.0).astype(np.float32))
        seen = inside_mask(induced_flow(depth, k_work, rel))  # a pixel that leaves the view has no flow to measure
        static = (area_downsample(((depth > 0) & ~moving & seen).astype(np.float32)) == 1.0).ravel()
        points = backproject(1.0 / np.maximum(grid_depth, 1e-9), k_grid)[static]
        gray_i, gray_j = (to_gray(prep.image(rgb(n))) for n in (i, j))
        for name in flows:
            t0 = time.perf_counter()
            start = induced_flow(depth, k_work, rel) if seeded or name == "gt" else None
            objects = dis_objects(*flow_spec(name), made)
            flow = start if name == "gt" else calc_deep(objects, gray_i, gray_j, start, coarsest_scale)
            ms = 1000 * (time.perf_counter() - t0)
            target = flow_to_target(flow).reshape(-1, 2)[static].astype(np.float64)
            norm = max(np.linalg.norm(rel[:3, 3]), 1e-12)
            est = solve_motion(points, target, k_grid, rel)
            held = solve_motion(points, target, k_grid, rel, translation_only=True)  # the rotation stays the truth
            cos = (np.trace(est[:3, :3] @ rel[:3, :3].T) - 1) / 2
            stats[name].append((np.linalg.norm(est[:3, 3]) / norm, np.linalg.norm(held[:3, 3]) / norm,
                                np.degrees(np.arccos(np.clip(cos, -1, 1))), ms))
    rows = []
    for name, v in stats.items():
        a = np.array(v)
        rows.append([f"{preset} seed {seed}", gap, name, f"{np.median(a[:, 0]):.4f}",
                     f"{np.percentile(a[:, 0], 10):.4f} / {np.percentile(a[:, 0], 90):.4f}",
                     f"{np.median(a[:, 1]):.4f}", f"{np.median(a[:, 2]):.3f}", "–" if name == "gt" else f"{np.median(a[:, 3]):.1f}"])
    return rows


def flow_spec(name: str) -> tuple[str, float]:
    """``"medium@2"`` → (``"medium"``, 2.0): a DIS preset and its smoothness α (``correspondence.smoothness``)."""
    preset, _, alpha = name.partition("@")
    return preset, float(alpha or 0.0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--presets", nargs="+", default=["walk", "rotate"])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--gaps", type=int, nargs="+", default=[4, 8])
    ap.add_argument("--pairs", type=int, default=12)
    ap.add_argument("--flows", nargs="+", default=["gt", "medium", "fine", "fast"],
                    help="gt or DIS presets; PRESET@A sets the smoothness α (e.g. medium@2)")
    ap.add_argument("--seeded", action="store_true", help="start DIS from the flow the true pose induces")
    ap.add_argument("--target-area", type=int, default=196608, help="working size in pixels (default: 384 × 512)")
    ap.add_argument("--coarsest-scale", type=int, default=0,
                    help="DIS's coarsest level at least 1/2^K of the working size, by padding (0: DIS's own)")
    args = ap.parse_args()
    from droidw_cli.correspondence.dis import PRESETS

    unknown = [f for f in args.flows if f != "gt" and flow_spec(f)[0] not in PRESETS]
    if unknown:
        ap.error(f"unknown flow(s) {unknown}: gt or one of {', '.join(PRESETS)}")
    rows = [row for preset in args.presets for gap in args.gaps
            for row in measure(preset, args.seed, gap, args.pairs, args.flows, args.target_area, args.seeded,
                                   args.coarsest_scale)]
    start = ", DIS started from the true induced flow" if args.seeded else ""
    print(f"Translation scale from the flow with exact depth (working area {args.target_area} px, BA grid 1/8{start})")
    print_table(["sequence", "gap", "flow", "‖t‖/‖t_true‖ median", "p10 / p90", "with the true rotation",
                 "rot err [deg]", "ms per flow"], rows)


if __name__ == "__main__":
    main()
