"""The forward-moving cameras (walk, ride, drive down a street), the street, its sky and its movers."""

from __future__ import annotations

import numpy as np
import pytest

from droidw_cli.synth import SynthConfig, build_scene
from droidw_cli.synth.config import FORWARD_MOTIONS, KITTI_CAMERA

SMALL = {"width": 160, "height": 120}
#: (frames, fps, mean speed range m/s) of each family as its preset runs it
RUNS = {"forward": (450, 30.0, (1.2, 1.6)), "ride": (240, 30.0, (4.0, 6.0)), "drive": (100, 10.0, (8.0, 15.0))}


def _angle(ra: np.ndarray, rb: np.ndarray) -> np.ndarray:
    rel = np.einsum("...ji,...jk->...ik", ra, rb)
    return np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))


@pytest.fixture(scope="module", params=FORWARD_MOTIONS)
def street(request):
    motion = request.param
    frames, fps, _ = RUNS[motion]
    cfg = SynthConfig(motion=motion, frames=frames, fps=fps, movers=3, seed=2, depth_scale=256.0, max_depth=250.0,
                      **SMALL)
    sc = build_scene(cfg)
    return motion, sc, sc.pose(np.arange(frames))


def test_the_camera_travels_forward_along_the_street(street):
    motion, sc, poses = street
    frames, fps, (lo, hi) = RUNS[motion]
    rot, pos = poses[:, :3, :3], poses[:, :3, 3]
    np.testing.assert_allclose(np.einsum("nji,njk->nik", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)
    speed = np.linalg.norm(pos[-1] - pos[0]) / ((frames - 1) / fps)
    assert lo * 0.95 <= speed <= hi * 1.05
    step = np.diff(pos, axis=0)
    assert np.all(step[:, 1] > 0)  # always forward along +y
    axis = rot[:, :, 2]  # the optical axis looks down the street, the way the camera goes
    assert np.all(axis[:, 1] > np.cos(np.radians(20))) and np.mean(axis[:, 1]) > np.cos(np.radians(12))
    assert _angle(rot[:-1], rot[1:]).max() < 3.0  # smooth: no jumps between frames
    np.testing.assert_array_equal(build_scene(sc.cfg).pose(np.arange(0, frames, 7)), poses[::7])


def test_the_street_is_seen_in_depth_with_sky_at_infinity(street):
    motion, sc, poses = street
    for k in (0, len(poses) // 2, len(poses) - 1):
        rgb, depth, _ = sc.render(k)
        sky = depth == 0
        assert 0.02 < sky.mean() < 0.5 and sky[0].mean() > 0.2  # the top row is partly sky, the bottom none
        assert not sky[-1].any() and depth[depth > 0].min() > 1.0  # nothing right in front of the lens
        assert np.percentile(depth[depth > 0], 95) > 20.0  # the street goes on far ahead
    rgb, depth, _ = sc.render(0)
    moved = poses[0].copy()
    moved[:3, 3] += [0.0, 3.0, 0.0]
    rgb2, depth2, _ = sc.render(0, pose_c2w=moved, movers=False)
    both = (depth == 0) & (depth2 == 0)
    assert both.mean() > 0.02
    diff = np.abs(rgb.astype(int) - rgb2.astype(int))[both]  # the sky does not move with a translation ...
    assert np.median(diff) <= 4  # (noise and JPEG apart) ...
    near = (depth > 0) & (depth < 15) & (depth2 > 0)
    assert np.median(np.abs(rgb.astype(int) - rgb2.astype(int))[near]) > 8  # ... the street does


def test_movers_cross_the_view(street):
    motion, sc, poses = street
    ks = np.arange(0, len(poses), max(1, len(poses) // 60))
    cover = np.array([sc.render(int(k))[2].mean() for k in ks])
    assert cover.max() > 0.01 and np.mean(cover > 0) > 0.3
    if motion == "drive":  # cars, as boxes about 4.5 m long
        assert any(max(2 * h[1] for h in w.halves) > 3.5 for w in sc.walkers)


def test_forward_presets():
    drive = SynthConfig.preset("drive")
    assert {k: getattr(drive, k) for k in KITTI_CAMERA} == KITTI_CAMERA and drive.fps == 10.0
    assert (SynthConfig.preset("forward").frames, SynthConfig.preset("ride").frames) == (450, 240)
    assert SynthConfig.preset("forward").rho == pytest.approx(525.0 / 4)  # the street's default texel density
    grey = build_scene(SynthConfig.preset("forward-small", grey=True, frames=3)).frame(1).rgb
    assert np.array_equal(grey[..., 0], grey[..., 1]) and np.array_equal(grey[..., 1], grey[..., 2])
