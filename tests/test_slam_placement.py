"""Placing a new keyframe against its predecessor (slam/placement.py): only its pose and disparity move."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.config import load_config
from droidw_cli.slam.frontend import Frontend
from droidw_cli.slam.optimizer import window_state
from droidw_cli.slam.placement import place_keyframe
from test_slam_backend import GRID, K8, _NoMatch

TRUE_K = torch.tensor([0.02, -0.01, -0.30, 0.0, 0.0, 0.0, 1.0])  # world-to-camera: 30 cm forward, a little sideways
GUESS_K = torch.tensor([0.06, 0.03, -0.29, 0.01, -0.01, 0.0, 0.9999])  # a guess off in direction and rotation


def _two_keyframes(sets=()):
    """Keyframe 0 at the identity, keyframe 1 at its guess, exact correspondences cached both ways."""
    cfg = load_config("default", ["uncertainty.enable=false", *sets])
    fe = Frontend(cfg, cfg.ba, get_backend("cpu"), _NoMatch(), GRID, K8, 0)
    h, w = GRID
    ys = torch.arange(h, dtype=torch.float32)[:, None].expand(h, w)
    disp = 1.0 / (2.0 + 0.05 * ys)  # a floor-like depth ramp, 2-3.2 m
    image = np.full((h * 8, w * 8, 3), 128, np.uint8)
    fe.buffer.append(0, 0.0, torch.tensor([0, 0, 0, 0, 0, 0, 1.0]), disp, image[::8, ::8])
    fe.buffer.append(4, 4 / 30.0, TRUE_K, disp, image[::8, ::8])  # the truth, to make the targets
    fe.initialised = True
    state = window_state(fe.buffer, 0, 2, fe.shared, with_features=False)
    ii, jj = torch.tensor([0, 1]), torch.tensor([1, 0])
    coords, valid = fe.backend.reproject(state, ii, jj, fe.params.min_depth)
    for e, (i, j) in enumerate([(0, 1), (1, 0)]):
        weight = valid[e].float()[..., None].expand(h, w, 2).contiguous()
        fe.cache.put(i, j, coords[e].contiguous(), weight)
    fe.buffer.poses[1] = GUESS_K
    fe.buffer.disps[1] = disp.mean()
    return fe, disp


def _error(fe):
    """Angle (degrees) between keyframe 1's translation and the truth's, plus its rotation error: the
    placement holds keyframe 0's pose but not the pair's scale (keyframe 0's disparity moves with it)."""
    t, q = fe.buffer.poses[1, :3], fe.buffer.poses[1, 3:] / fe.buffer.poses[1, 3:].norm()
    cos = torch.dot(t, TRUE_K[:3]) / (t.norm() * TRUE_K[:3].norm())
    rot = 2 * torch.arccos(torch.abs(torch.dot(q, TRUE_K[3:])).clamp(max=1.0))
    return float(torch.rad2deg(torch.arccos(cos.clamp(-1.0, 1.0)) + rot))


def test_the_new_keyframe_moves_to_its_pose_and_its_predecessor_stays():
    fe, disp = _two_keyframes()
    before = _error(fe)
    iterations = fe.shared.iterations
    place_keyframe(fe, 1, fe.fcfg.place_iters)
    assert _error(fe) < 0.1 * before, (before, _error(fe))
    torch.testing.assert_close(fe.buffer.poses[0], torch.tensor([0, 0, 0, 0, 0, 0, 1.0]))
    torch.testing.assert_close(fe.buffer.disps[0], disp)  # the predecessor's disparity is put back
    assert fe.shared.iterations == iterations  # no window BA iteration counted
    assert fe.correspondence.asked == []  # the cached pair was used, nothing matched again


def test_no_placement_iterations_leave_the_guess():
    fe, _ = _two_keyframes(["frontend.place_iters=0"])
    place_keyframe(fe, 1, fe.fcfg.place_iters)
    torch.testing.assert_close(fe.buffer.poses[1], GUESS_K)


def test_negative_placement_iterations_are_refused():
    from droidw_cli.errors import ConfigError
    with pytest.raises(ConfigError, match="place_iters"):
        load_config("default", ["frontend.place_iters=-1"])
