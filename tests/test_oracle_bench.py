"""benchmarks/oracle_bench.py: its model flow is the BA's own reprojection of each cell centre, and it
differs from the block mean of the true per-pixel flow exactly where that flow is not affine."""

from __future__ import annotations

import numpy as np
import torch
from bench_scripts import load
from scipy.spatial.transform import Rotation

from droidw_cli.correspondence.grid import flow_to_target
from droidw_cli.geometry.camera import scale_intrinsics
from droidw_cli.geometry.projection import reproject

bench = load("oracle_bench")

K_WORK = np.array([420.0, 420.0, 255.5, 191.5])
H, W = 384, 512


def _forward(dz: float = 0.4, yaw: float = 0.01) -> np.ndarray:
    """A step dz along the optical axis with a small yaw (4×4, camera i → camera j)."""
    c, s = np.cos(yaw), np.sin(yaw)
    rel = np.eye(4)
    rel[:3, :3] = [[c, 0, s], [0, 1, 0], [-s, 0, c]]
    rel[:3, 3] = [0.02, -0.01, -dz]
    return rel


def _ground(height: float = 1.5) -> np.ndarray:
    """Depth of a ground plane seen by a camera looking along it (sky above the horizon: 0)."""
    ys = np.mgrid[0:H, 0:W][0].astype(np.float64)
    below = ys - K_WORK[3]
    return np.where(below > 1, height * K_WORK[1] / np.maximum(below, 1e-9), 0.0).astype(np.float32)


def test_the_model_flow_is_the_backends_reprojection_of_the_cell_centres():
    depth = np.linspace(2.0, 9.0, H * W, dtype=np.float32).reshape(H, W)
    rel = _forward()
    target = flow_to_target(bench.model_flow(depth, K_WORK, rel))
    inv = (1.0 / depth).reshape(H // 8, 8, W // 8, 8).mean(axis=(1, 3))

    pose_j = np.concatenate([rel[:3, 3], Rotation.from_matrix(rel[:3, :3]).as_quat()])
    poses = torch.tensor(np.stack([[0, 0, 0, 0, 0, 0, 1.0], pose_j]), dtype=torch.float64)
    disps = torch.tensor(np.stack([inv, inv]), dtype=torch.float64)
    k_grid = torch.tensor(scale_intrinsics(K_WORK, 8), dtype=torch.float64)
    coords = reproject(poses, disps, k_grid, torch.tensor([0]), torch.tensor([1]))[0][0].numpy()
    assert np.abs(target - coords).max() < 1e-3


def test_the_block_mean_of_the_true_flow_leaves_the_model_only_where_the_flow_is_not_affine():
    rel = _forward()
    for depth, lo, hi in ((np.full((H, W), 5.0, np.float32), 0.0, 5e-5), (_ground(), 2.5e-4, np.inf)):
        exact = flow_to_target(bench.induced_flow(depth, K_WORK, rel))
        model = flow_to_target(bench.model_flow(depth, K_WORK, rel))
        seen = (depth.reshape(H // 8, 8, W // 8, 8) > 0).all(axis=(1, 3))
        gap = np.linalg.norm(exact - model, axis=-1)[seen]
        assert lo <= float(np.mean(gap)) < hi


def test_the_mask_oracle_zeroes_every_cell_a_movers_pixel_touches(tmp_path):
    """``exact-mask``: a cell of the 1/8 grid is a mover's when any of its working-size pixels is, after the
    source frame went through the tracker's preparation (resize and crop)."""
    import cv2

    from droidw_cli.io.prepare import FramePreparer

    mask = np.zeros((480, 640), np.uint8)
    mask[100:103, 200:202] = 1  # a few source pixels: one or two cells at the working size 384 × 512
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    truth = bench.GroundTruth.__new__(bench.GroundTruth)
    truth.folder, truth.masks = tmp_path, ["m.png"]
    truth.prep = FramePreparer((480, 640), K_WORK, target_area=H * W)
    cells = truth.mover_cells(0, (H // 8, W // 8))
    assert cells.shape == (48, 64) and 1 <= cells.sum() <= 4
    ys, xs = np.nonzero(cells)
    assert set(ys) <= {9, 10} and set(xs) <= {19, 20}  # (100..102) · 0.8 / 8 and (200..201) · 0.8 / 8
    truth.masks = []
    assert not truth.mover_cells(0, (48, 64)).any()
