"""Umeyama alignment: recovery of known transforms, reflection fix, degenerate inputs, evo agreement."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.errors import InputError
from droidw_cli.eval.align import DegenerateGeometryError, Sim3, align_positions, check_not_degenerate, umeyama


def rotation_about(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float)
    k = k / np.linalg.norm(k)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx


@pytest.fixture
def cloud() -> np.ndarray:
    return np.random.default_rng(0).normal(size=(60, 3)) * np.array([2.0, 1.0, 0.5])


def test_recovers_exact_sim3(cloud):
    r = rotation_about([0.3, -1.0, 0.4], 1.1)
    t = np.array([4.0, -2.0, 0.5])
    s = 2.7
    dst = s * cloud @ r.T + t
    est = umeyama(cloud, dst, with_scale=True)
    np.testing.assert_allclose(est.rotation, r, atol=1e-12)
    np.testing.assert_allclose(est.translation, t, atol=1e-12)
    assert est.scale == pytest.approx(s, rel=1e-12)
    np.testing.assert_allclose(est.apply_points(cloud), dst, atol=1e-11)


def test_se3_keeps_unit_scale_and_noise_is_tolerated(cloud):
    rng = np.random.default_rng(1)
    r = rotation_about([1.0, 1.0, 0.0], -0.7)
    dst = cloud @ r.T + np.array([0.1, 0.2, 0.3]) + rng.normal(scale=1e-3, size=cloud.shape)
    est = align_positions(cloud, dst, "se3")
    assert est.scale == 1.0
    assert np.abs(est.rotation - r).max() < 5e-3
    assert np.linalg.det(est.rotation) == pytest.approx(1.0)


def test_reflection_fix_gives_a_proper_rotation(cloud):
    mirrored = cloud * np.array([1.0, 1.0, -1.0])  # a reflection, not reachable by a rotation
    est = umeyama(cloud, mirrored, with_scale=True)
    assert np.linalg.det(est.rotation) == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(est.rotation @ est.rotation.T, np.eye(3), atol=1e-12)
    # the naive U Vᵀ would be the reflection itself and fit perfectly; the proper one cannot
    assert np.abs(est.apply_points(cloud) - mirrored).max() > 0.1


def test_none_is_identity(cloud):
    est = align_positions(cloud, cloud + 5.0, "none")
    np.testing.assert_array_equal(est.apply_points(cloud), cloud)
    with pytest.raises(ValueError):
        align_positions(cloud, cloud, "affine")


def test_apply_poses_matches_apply_points(cloud):
    rng = np.random.default_rng(2)
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, :3, :3] = [rotation_about(rng.normal(size=3), rng.uniform(0, 3)) for _ in range(5)]
    poses[:, :3, 3] = cloud[:5]
    sim = Sim3(rotation_about([0, 0, 1], 0.5), np.array([1.0, 2.0, 3.0]), 0.5)
    out = sim.apply_poses(poses)
    np.testing.assert_allclose(out[:, :3, 3], sim.apply_points(cloud[:5]))
    np.testing.assert_allclose(out[:, :3, :3], sim.rotation @ poses[:, :3, :3])
    np.testing.assert_allclose(np.linalg.det(out[:, :3, :3]), 1.0)


@pytest.mark.parametrize(
    "points",
    [
        np.tile([[1.0, 2.0, 3.0]], (10, 1)),  # identical
        np.outer(np.linspace(0, 5, 10), [1.0, -2.0, 0.5]) + 7.0,  # collinear
        np.tile([[1e6, -1e6, 3.0]], (4, 1)) + np.array([[0, 0, 0], [1e-10, 0, 0], [0, 0, 0], [0, 0, 0]]),
    ],
)
def test_degenerate_positions_raise_input_errors(points):
    with pytest.raises(DegenerateGeometryError, match="degenerate geometry"):
        check_not_degenerate(points)
    good = np.random.default_rng(3).normal(size=points.shape)
    with pytest.raises(InputError):
        umeyama(good, points)
    with pytest.raises(InputError):
        umeyama(points, good)


def test_planar_positions_are_fine():
    rng = np.random.default_rng(4)
    planar = np.c_[rng.normal(size=(30, 2)), np.zeros(30)]
    check_not_degenerate(planar)
    r = rotation_about([0, 1, 1], 0.3)
    est = umeyama(planar, 1.5 * planar @ r.T, with_scale=True)
    np.testing.assert_allclose(est.rotation, r, atol=1e-10)
    assert est.scale == pytest.approx(1.5)


def test_agrees_with_evo_umeyama():
    geometry = pytest.importorskip("evo.core.geometry")
    rng = np.random.default_rng(5)
    for _ in range(5):
        x = rng.normal(size=(40, 3)) * rng.uniform(0.1, 3, size=3)
        y = rng.normal(size=(40, 3)) * 0.1 + 1.3 * x @ rotation_about(rng.normal(size=3), 2.0).T
        for with_scale in (True, False):
            r, t, c = geometry.umeyama_alignment(x.T, y.T, with_scale)
            ours = umeyama(x, y, with_scale)
            np.testing.assert_allclose(ours.rotation, r, atol=1e-10)
            np.testing.assert_allclose(ours.translation, t, atol=1e-10)
            assert ours.scale == pytest.approx(c, rel=1e-10)
