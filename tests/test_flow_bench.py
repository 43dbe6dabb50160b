"""benchmarks/flow_bench.py: its motion-only solver recovers the true translation from an exact flow,
reads a flow whose parallax is compressed as a shorter translation, and with the rotation held at the
truth reads that compression itself."""

from __future__ import annotations

import numpy as np
from bench_scripts import load

from droidw_cli.correspondence.grid import flow_to_target
from droidw_cli.geometry.camera import scale_intrinsics

bench = load("flow_bench")

K_WORK = np.array([420.0, 420.0, 255.5, 191.5])
K_GRID = scale_intrinsics(K_WORK, 8)


def _scene():
    """A 384×512 depth of two slanted planes and a relative pose with translation and rotation."""
    ys, xs = np.mgrid[0:384, 0:512].astype(np.float32)
    depth = np.where(xs < 256, 2.0 + ys / 384, 4.0 - xs / 512).astype(np.float32)
    rel = bench._exp_se3(np.array([0.01, -0.02, 0.005, 0.06, -0.02, 0.03]))
    grid_depth = depth.reshape(48, 8, 64, 8).mean(axis=(1, 3))
    return depth, rel, bench.backproject(grid_depth, K_GRID)


def _translation_scale(flow, rel, points, start=None, translation_only=False):
    start = np.eye(4) if start is None else start
    est = bench.solve_motion(points, flow_to_target(flow).reshape(-1, 2).astype(np.float64), K_GRID, start,
                             translation_only=translation_only)
    return np.linalg.norm(est[:3, 3]) / np.linalg.norm(rel[:3, 3])


def test_the_solver_recovers_the_translation_from_the_induced_flow():
    depth, rel, points = _scene()
    assert abs(_translation_scale(bench.induced_flow(depth, K_WORK, rel), rel, points) - 1.0) < 2e-3


def _parallax_share(share: float):
    """(rel, points, rotation-only pose, flow whose translational part is ``share`` of the true one)."""
    depth, rel, points = _scene()
    rotation_only = rel.copy()
    rotation_only[:3, 3] = 0.0
    rot = bench.induced_flow(depth, K_WORK, rotation_only)
    return rel, points, rotation_only, rot + share * (bench.induced_flow(depth, K_WORK, rel) - rot)


def test_a_flow_with_compressed_parallax_reads_as_a_shorter_translation():
    rel, points, _, compressed = _parallax_share(0.95)  # the translation's share of the flow 5 % short
    assert _translation_scale(compressed, rel, points) < 0.97


def test_with_the_true_rotation_the_translation_reads_the_parallax_scale():
    for share in (1.0, 0.95):
        rel, points, rotation_only, flow = _parallax_share(share)
        assert abs(_translation_scale(flow, rel, points, start=rotation_only, translation_only=True) - share) < 0.01
    held = bench.solve_motion(points, flow_to_target(flow).reshape(-1, 2).astype(np.float64), K_GRID, rotation_only,
                              translation_only=True)
    np.testing.assert_allclose(held[:3, :3], rotation_only[:3, :3], atol=1e-12)  # the rotation does not move


def test_a_flow_name_may_carry_the_dis_smoothness():
    assert bench.flow_spec("medium") == ("medium", 0.0)
    assert bench.flow_spec("medium@2") == ("medium", 2.0)
