"""The start of a keyframe's first edge from the motion filter's half-size flow."""

from __future__ import annotations

import numpy as np

from droidw_cli.slam.starts import adjacent_start


def test_the_half_size_flow_is_brought_to_the_working_size_and_scaled():
    half = np.zeros((60, 80, 2), np.float32)
    half[..., 0], half[..., 1] = 3.0, -1.5
    full = adjacent_start(half, (120, 160), invert=False)
    assert full.shape == (120, 160, 2) and full.dtype == np.float32
    np.testing.assert_allclose(full[..., 0], 6.0, atol=1e-5)
    np.testing.assert_allclose(full[..., 1], -3.0, atol=1e-5)


def test_inverted_it_starts_the_flow_the_other_way():
    """A zoom about the centre, x → c + 1.1 (x − c): the inverse flow at y is what takes y back, so that
    y + f⁻¹(y) = c + (y − c) / 1.1, away from the borders where the zoom leaves the view."""
    h, w = 60, 80
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    centre = np.float32([(w - 1) / 2, (h - 1) / 2])
    grid = np.stack([xs, ys], -1)
    half = (grid - centre) * np.float32(0.1)
    back = adjacent_start(half, (h, w), invert=True)
    inner = (slice(10, -10), slice(12, -12))
    expected = centre + (grid - centre) / np.float32(1.1) - grid
    np.testing.assert_allclose(back[inner], expected[inner], atol=0.05)


K = np.array([262.5, 262.5, 159.5, 119.5])  # 320 × 240 at f = 262.5


def _scene_flow(rvec, t, size=(240, 320), seed=0):
    """The flow of a camera turning by ``rvec`` and moving by ``t`` over a scene 3-30 m deep."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = size
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    z = np.repeat(np.repeat(rng.uniform(3.0, 30.0, (h // 8, w // 8)), 8, 0), 8, 1)
    pts = np.stack([(xs - K[2]) / K[0] * z, (ys - K[3]) / K[1] * z, z], -1)
    rot, _ = cv2.Rodrigues(np.asarray(rvec, np.float64))
    cam = pts @ rot.T + np.asarray(t, np.float64)
    moved = np.stack([cam[..., 0] / cam[..., 2] * K[0] + K[2], cam[..., 1] / cam[..., 2] * K[1] + K[3]], -1)
    return (moved - np.stack([xs, ys], -1)).astype(np.float32), rot


def test_the_rotation_of_a_panning_camera_is_found_under_its_parallax():
    """A 4° pan (about 18 px at f = 262.5): found exactly alone, and within 0.25° beside a 5 cm sideways step
    (which a yaw of about 0.2° mimics over a scene 3-30 m deep: the start needs to take most of the flow
    away, not to be exact); its flow is what the rotation alone moves."""
    import cv2

    from droidw_cli.slam.starts import fit_rotation, rotation_flow

    def error(flow, rot):
        return np.degrees(np.linalg.norm(cv2.Rodrigues(fit_rotation(flow, K) @ rot.T)[0]))

    pure, rot = _scene_flow([0.01, np.radians(4.0), 0.005], [0.0, 0.0, 0.0])
    assert error(pure, rot) < 1e-4
    stepped, _ = _scene_flow([0.01, np.radians(4.0), 0.005], [0.05, 0.0, 0.02])
    assert 1e-3 < error(stepped, rot) < 0.25
    np.testing.assert_allclose(rotation_flow(rot, K, pure.shape[:2]), pure, atol=1e-3)


def test_a_rotation_start_only_where_dis_finds_the_rest_alone():
    """``rotation_start``: the rotation's flow when the rest of the flow averages under ``max_rest`` px, else
    the whole flow (a camera travelling into the scene needs its expansion in the start); a flow DIS takes as
    its initial flow (not warped out) stays whole."""
    from droidw_cli.correspondence.dis import WARP_MIN
    from droidw_cli.slam.starts import rotation_start

    pan, _ = _scene_flow([0.0, np.radians(4.0), 0.0], [0.05, 0.0, 0.0])
    turned = rotation_start(pan, K, max_rest=8.0)
    assert turned is not pan and float(np.abs(pan - turned).mean()) > 0.1  # the parallax is left to DIS
    small, _ = _scene_flow([0.0, np.radians(1.5), 0.0], [0.02, 0.0, 0.0])  # about 7 px: DIS's initial flow
    assert np.abs(small).mean() < WARP_MIN * 400 < np.abs(pan).mean()  # 400: the 240 × 320 image's diagonal
    assert rotation_start(small, K, max_rest=8.0) is small
    drive, _ = _scene_flow([0.0, np.radians(1.0), 0.0], [0.0, 0.0, 2.5])  # 2.5 m forward: large expansion
    assert rotation_start(drive, K, max_rest=8.0) is drive
    half = pan[::2, ::2] / 2
    np.testing.assert_array_equal(adjacent_start(half, (240, 320), False, K, 0.0), adjacent_start(half, (240, 320), False))


def test_the_mean_flow_length_sums_as_numpys_norm():
    """``mean_length`` (correspondence/grid.py) gives the very float of ``np.linalg.norm(flow, axis=-1).mean()``."""
    from droidw_cli.correspondence.grid import mean_length

    rng = np.random.default_rng(3)
    for scale in (0.3, 7.0, 40.0):
        flow = (rng.standard_normal((96, 128, 2)) * scale).astype(np.float32)
        assert mean_length(flow) == float(np.linalg.norm(flow, axis=-1).mean())
