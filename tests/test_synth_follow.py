"""Follow shots (synth.follow): the camera keeps the subject (mover 0) in the middle while the street streams past."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_synth_scene import reprojection_check

from droidw_cli.synth import PRESETS, SynthConfig, build_scene, layout
from droidw_cli.synth.config import FOLLOW_MOTIONS
from droidw_cli.synth.follow import aim_height

SMALL = {"width": 160, "height": 120}
EVERY = 10  # the subject's mask is checked on every 10th frame of the 450 (cast only: cheap)


@pytest.fixture(scope="module", params=FOLLOW_MOTIONS)
def follow(request):
    """The preset at 160 × 120 (450 frames, seed 1), its poses and the subject's mask on every EVERY-th frame."""
    sc = build_scene(SynthConfig.preset(request.param, seed=1, **SMALL))
    ks = np.arange(0, sc.cfg.frames, EVERY)
    return request.param, sc, sc.pose(np.arange(sc.cfg.frames)), ks, np.stack([subject_mask(sc, k) for k in ks])


def subject_mask(sc, k: int) -> np.ndarray:
    """Where the subject (mover 0) is the nearest surface at frame k."""
    pose = sc.pose(k)
    full = sc.caster.cast(sc.boxes(k), pose).depth
    alone = sc.caster.cast(sc.static_boxes + sc.walkers[0].boxes(float(sc.walker_time(k))), pose)
    return alone.dynamic & (alone.depth <= full + 1e-6)


def _backproject(sc, depth: np.ndarray, u: np.ndarray, v: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """World points (N, 3) of pixels (u, v) with their z-depths, seen from ``pose``."""
    rays = np.linalg.solve(sc.cfg.K, np.stack([u, v, np.ones_like(u)]).astype(np.float64))
    return (pose[:3, :3] @ (rays * depth[v, u].astype(np.float64))).T + pose[:3, 3]


def _project(sc, pts: np.ndarray, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    cam = (pts - pose[:3, 3]) @ pose[:3, :3]
    uvw = cam @ sc.cfg.K.T
    return uvw[:, :2] / uvw[:, 2:], cam[:, 2]


def _move_with_subject(sc, pts: np.ndarray, ka: int, kb: int) -> np.ndarray:
    """World points on the subject at frame ka carried rigidly with its body to frame kb."""
    (ra, pa), (rb, pb) = (sc.walkers[0].walk.state(float(sc.walker_time(k))) for k in (ka, kb))
    return ((pts - pa) @ ra) @ rb.T + pb


def test_the_subject_stays_in_the_middle(follow):
    motion, sc, _, ks, masks = follow
    w, h = sc.cfg.width, sc.cfg.height
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    for k, m in zip(ks, masks):
        assert m.sum() > 0.005 * m.size, (motion, k)  # seen, and not a sliver
        v, u = np.nonzero(m)
        assert np.hypot(*(np.array([u.mean(), v.mean()]) - centre)) <= 0.1 * w, (motion, k)
    # the aim point itself projects within the tracking error (≤ 3°) of the principal point, on every frame
    cam, t = sc.camera, sc.camera_time(np.arange(sc.cfg.frames))
    rel = np.einsum("nji,nj->ni", cam.rotation(t), cam.aim(t) - cam.position(t))
    assert np.degrees(np.arctan2(np.hypot(rel[:, 0], rel[:, 1]), rel[:, 2])).max() < 3.0
    assert sc.camera.aim_height == aim_height(layout.walker_specs(1, 0)) and 0.6 < sc.camera.aim_height < 1.0


def test_the_camera_follows_as_a_walker_would(follow):
    motion, sc, poses, _, _ = follow
    rot, pos = poses[:, :3, :3], poses[:, :3, 3]
    np.testing.assert_allclose(np.einsum("nji,njk->nik", rot, rot), np.broadcast_to(np.eye(3), rot.shape), atol=1e-12)
    rel = np.einsum("nji,njk->nik", rot[:-1], rot[1:])
    step_deg = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert step_deg.max() < 2.0 and np.all(np.diff(pos[:, 1]) > 0)  # smooth; walking along the street
    aim = sc.camera.aim(sc.camera_time(np.arange(sc.cfg.frames)))
    ground = np.linalg.norm((aim - pos)[:, :2], axis=1)
    heading = np.degrees(np.arctan2(rot[:, 0, 2], rot[:, 1, 2]))  # the optical axis from +y, about z
    if motion == "follow":  # 2.5-4 m behind, panning with the weave
        assert 2.5 <= ground.min() and ground.max() <= 4.0
        assert np.all(aim[:, 1] > pos[:, 1]) and 5.0 < np.ptp(heading) < 60.0
    else:  # side-on: abeam in the middle, from behind to ahead
        assert 2.5 <= ground.min() <= 4.5
        assert abs(abs(heading[len(heading) // 2]) - 90.0) < 15.0 and np.ptp(heading) > 100.0


def test_the_background_streams_past_the_subject(follow):
    """Ground-truth flow from depth and poses (the subject's carried with its body) over 2 frames:
    the background's median is several times the subject's."""
    motion, sc, _, ks, masks = follow
    ratios = []
    for k, m in zip(ks[1:-1:6], masks[1:-1:6]):
        f = sc.frame(int(k))
        pose_a, pose_b = sc.pose(int(k)), sc.pose(int(k) + 2)
        v, u = np.nonzero(~f.mask & (f.depth > 0))
        bg = _project(sc, _backproject(sc, f.depth, u, v, pose_a), pose_b)[0] - np.stack([u, v], 1)
        v, u = np.nonzero(m)
        pts = _move_with_subject(sc, _backproject(sc, f.depth, u, v, pose_a), int(k), int(k) + 2)
        sub = _project(sc, pts, pose_b)[0] - np.stack([u, v], 1)
        ratios.append(np.median(np.linalg.norm(bg, axis=1)) / max(np.median(np.linalg.norm(sub, axis=1)), 1e-3))
    assert np.median(ratios) > 4.0 and min(ratios) > 1.0, ratios


def test_the_ground_truth_is_consistent(follow):
    """Static pixels reproject exactly with the GT depth and poses; the subject's pixels, carried with its body,
    land on the subject in the next frame at its depth there."""
    motion, sc, _, ks, _ = follow
    for k in ks[[3, 22]]:
        a, b = sc.frame(int(k)), sc.frame(int(k) + 1)
        res = reprojection_check(a, b, sc.cfg.K)  # (the ground, seen at a grazing angle, mostly fails its 1 % test)
        assert res["count"] > 0.15 * a.mask.size and res["err"] < 0.02, res
        wrong = reprojection_check(a, b, sc.cfg.K, pose_b=sc.pose(int(k) + 9))
        assert wrong["count"] < 0.5 * res["count"] or wrong["err"] > 0.1, wrong
        ma, mb = subject_mask(sc, int(k)), subject_mask(sc, int(k) + 1)
        v, u = np.nonzero(ma)
        uv, z = _project(sc, _move_with_subject(sc, _backproject(sc, a.depth, u, v, a.pose_c2w), int(k), int(k) + 1),
                         b.pose_c2w)
        ui, vi = np.round(uv).astype(int).T
        inside = (ui >= 0) & (vi >= 0) & (ui < sc.cfg.width) & (vi < sc.cfg.height)
        ui, vi, z = ui[inside], vi[inside], z[inside]
        assert inside.mean() > 0.95 and mb[vi, ui].mean() > 0.9
        assert np.median(np.abs(b.depth[vi, ui] - z) / z) < 0.01


def test_other_movers_and_the_static_variant():
    cfg = SynthConfig.preset("follow", seed=2, **SMALL)
    sc = build_scene(cfg)
    assert len(sc.walkers) == 3 and sc.walkers[0].walk is sc.camera.subject
    seen = sum(bool((sc.render(int(k))[2] & ~subject_mask(sc, int(k))).any()) for k in range(0, 450, 30))
    assert seen >= 2  # the others come into view now and then
    still = build_scene(cfg.replace(static=True))
    np.testing.assert_array_equal(still.pose(np.arange(0, 450, 9)), sc.pose(np.arange(0, 450, 9)))
    assert not still.render(200)[2].any()


def test_follow_presets_and_cli(tmp_path, capsys):
    from droidw_cli.cli import main

    for name in FOLLOW_MOTIONS:
        cfg = SynthConfig.preset(name)
        assert name in PRESETS and cfg.motion == name and (cfg.width, cfg.height, cfg.fps, cfg.frames) == (
            640, 480, 30.0, 450)
        assert cfg.blur > 0 and cfg.jpeg_quality == 75 and cfg.noise_std > 0 and cfg.movers == 3
    control = SynthConfig.preset("follow-static", seed=2)  # the static control: the same path, nobody rendered
    assert control == SynthConfig.preset("follow", seed=2, static=True) and control.n_movers == 0
    out = tmp_path / "follow"
    main(["synth", str(out), "--preset", "follow", "--frames", "3", "--size", "64x48"])
    assert "follow camera" in capsys.readouterr().out
    assert json.loads((out / "synth.json").read_text())["config"]["motion"] == "follow"
    assert len(list((out / "mask").iterdir())) == 3
