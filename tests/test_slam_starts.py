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
