"""Follow shots: a camera in a street that pans to keep one mover, the subject, in the middle of the frame.

World frame as in :mod:`droidw_cli.synth.street` (x across, y along the
street, z up, metres).  Mover 0 is the subject.  It walks on the ground
(walker time τ, seconds) with waves W (:class:`~droidw_cli.synth.paths.Wave`):

    S(τ) = (x_s + W_x(τ),  y_s + v_s (τ − τ₀) + W_y(τ),  b |sin(½ ω_step τ)|)

facing its velocity Ṡ (body frame as every walker's: R_body = R_z(θ − π/2),
θ = atan2(Ṡ_y, Ṡ_x)).  The camera walks (camera time t)

    p(t) = (x_c + W_lat(t),  y_c + v_c t + W_surge(t),  z_c + W_bob(t))

and aims at the subject's silhouette centre A(t) = S(ρ t) + (0, 0, h_A), where
ρ = mover_speed / camera_speed maps camera time to walker time (both clocks
tick with their own speed factor; ρ = 0 for a still camera clock) and
h_A = Σᵢ wᵢ hᵢ zᵢ / Σᵢ wᵢ hᵢ is the mean height of the subject's parts
(width wᵢ, height hᵢ, centre zᵢ) seen from the front, where its mask's
centroid lies:

    R(t) = R_lookat(p(t), A(t)) · R_z(W_roll(t)) · R_x(W_pitch(t)) · R_y(W_yaw(t)).

Without the waves on the right, A projects exactly on the principal point
(R_lookat's third column is (A − p)/‖A − p‖).  The waves are the operator's
tracking error, 1-1.5° (with a 0.3-0.4° tremor): A's image is off the
centre by about f tan(yaw) horizontally, ≤ 25 px at 640 × 480 (f = 525),
well inside the 10 % of the width (64 px) the subject keeps to.

Motion blur (:mod:`droidw_cli.synth.exposure`) needs nothing new: each
sub-frame s of the exposure takes the camera pose and the movers at time s,
and as the camera re-aims at the subject at every s, the subject's image
hardly smears while a static point at depth Z streams past at about
f (ω + v⊥ / Z) pixels a second (ω the pan rate, v⊥ the camera's speed across
the line of sight): the background blurs, the subject stays sharp.

Two families:

* ``follow``: a walk 2.5-4 m behind a walker (1.1-1.5 m/s) who weaves
  ±0.4-0.6 m across a wide sidewalk every 5.5-7.5 s; the camera walks at the
  same mean speed, 0.3-0.7 m to one side, its gap breathing by ±0.2 m, with
  the step bob and sway of the ``forward`` walk; the pan follows the weave
  (up to ±30°).
* ``follow-pan``: the camera strolls along the outer part of the sidewalk
  (0.3-0.6 m/s) while a brisk walker or jogger 1.0-1.3 m/s faster
  overtakes on the road 2.5-4.5 m away, abeam at the middle frame: the
  camera pans side-on from behind to ahead (±60-75° over 450 frames, up
  to 0.5 rad/s abeam), the background streaming sideways.

The other movers are the street's roles (:mod:`~droidw_cli.synth.street_world`):
an oncoming walker, one on the far sidewalk (small and far), a crosser.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.synth import layout, street
from droidw_cli.synth.config import FOLLOW_MOTIONS, SynthConfig
from droidw_cli.synth.layout import BoxSpec
from droidw_cli.synth.motions import DEG, compose_pose
from droidw_cli.synth.paths import Wave, look_at, rot_x, rot_y, rot_z
from droidw_cli.synth.street_world import TAG_MOVER, StreetWorld, mover_path, street_statics

#: the other movers' roles (mover 0 is the subject)
ROLES = {"follow": ("oncoming", "far", "crossing"), "follow-pan": ("far", "crossing", "oncoming")}
TAG_FOLLOW = 30  # the camera's random stream: [seed, TAG_CAMERA, TAG_FOLLOW]


@dataclass(frozen=True)
class WeaveWalk:
    """The subject's path S(τ) (module docstring): a line at ``velocity`` through ``origin`` at τ₀, plus waves."""

    origin: tuple[float, float]
    velocity: tuple[float, float]
    t0: float
    weave: Wave  # across (x)
    surge: Wave  # along (y)
    bob: float = 0.015
    step_omega: float = 2 * np.pi * 1.8

    def state(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Body-to-world rotations (…, 3, 3) and body origins on the ground (…, 3), as LineWalk.state."""
        t = np.asarray(t, np.float64)
        x = self.origin[0] + (t - self.t0) * self.velocity[0] + self.weave(t)
        y = self.origin[1] + (t - self.t0) * self.velocity[1] + self.surge(t)
        heading = np.arctan2(self.velocity[1] + self.surge.rate(t), self.velocity[0] + self.weave.rate(t))
        z = self.bob * np.abs(np.sin(0.5 * self.step_omega * t))
        return rot_z(heading - np.pi / 2), np.stack([x, y, z], -1)


@dataclass(frozen=True)
class FollowPath:
    """A camera walking along +y and aiming at the subject (module docstring); angles in radians."""

    start: tuple[float, float, float]
    speed: float
    surge: Wave
    lateral: Wave
    bob: Wave
    subject: WeaveWalk
    aim_height: float
    ratio: float  # walker time per camera time
    shake: tuple[Wave, Wave, Wave]  # roll, pitch, yaw about the camera axes: the tracking error

    def position(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)
        x0, y0, z0 = self.start
        return np.stack([x0 + self.lateral(t), y0 + self.speed * t + self.surge(t), z0 + self.bob(t)], -1)

    def aim(self, t) -> np.ndarray:
        """A(t): the subject's silhouette centre at camera time t."""
        _, pos = self.subject.state(self.ratio * np.asarray(t, np.float64))
        return pos + np.array([0.0, 0.0, self.aim_height])

    def rotation(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)
        roll, pitch, yaw = (w(t) for w in self.shake)
        return look_at(self.position(t), self.aim(t)) @ rot_z(roll) @ rot_x(pitch) @ rot_y(yaw)

    def target(self, t) -> np.ndarray:
        return self.position(t) + 10.0 * self.rotation(t)[..., :, 2]

    def pose(self, t) -> np.ndarray:
        return compose_pose(self.rotation(t), self.position(t))


def aim_height(parts: list[BoxSpec]) -> float:
    """h_A: the mean height of the parts' front silhouettes (width × height), weighted by their areas."""
    area = np.array([4.0 * p.half[0] * p.half[2] for p in parts])
    return float(area @ np.array([p.centre[2] for p in parts]) / area.sum())


def follow_path(cfg: SynthConfig, plan: street.StreetPlan, subject_parts: list[BoxSpec]) -> FollowPath:
    """The camera of follow family ``cfg.motion`` with its subject (drawn from the seed's own streams)."""
    rng = np.random.default_rng([cfg.seed, layout.TAG_CAMERA, TAG_FOLLOW])
    srng = np.random.default_rng([cfg.seed, TAG_MOVER, 0])
    ratio = cfg.mover_speed / cfg.camera_speed if cfg.camera_speed > 0 else 0.0
    h_aim = aim_height(subject_parts)
    step_omega = 2 * np.pi * srng.uniform(1.6, 2.0)
    if cfg.motion == "follow":
        speed, step = rng.uniform(1.1, 1.5), rng.uniform(1.7, 2.1)
        gap, side = rng.uniform(3.0, 3.3), float(rng.choice([-1.0, 1.0]))
        subject = WeaveWalk((plan.lane_x, 0.0), (0.0, speed), 0.0,
                            weave=Wave.random(srng, [srng.uniform(0.6, 0.9), 0.1], [5.5, 2.3]),
                            surge=Wave.random(srng, [0.2, 0.04], [7.0, 2.9]), step_omega=step_omega)
        return FollowPath(
            start=(plan.lane_x + side * rng.uniform(0.3, 0.7), -gap, rng.uniform(1.45, 1.65)), speed=speed,
            surge=Wave.random(rng, [0.2, 0.03], [8.0, 1.0 / step]),
            lateral=Wave.random(rng, [0.15, 0.012], [9.0, 2.0 / step]),
            bob=Wave.random(rng, [rng.uniform(0.02, 0.03), 0.006], [1.0 / step, 0.5 / step]),
            subject=subject, aim_height=h_aim, ratio=ratio,
            shake=(Wave.random(rng, [1.0 * DEG, 0.3 * DEG], [1.0 / step, 0.35]),
                   Wave.random(rng, [0.5 * DEG, 0.1 * DEG], [2.9, 0.4]),
                   Wave.random(rng, [0.8 * DEG, 0.1 * DEG], [3.7, 0.45])))
    if cfg.motion == "follow-pan":
        speed, step = rng.uniform(0.3, 0.6), rng.uniform(1.4, 1.8)
        z0 = rng.uniform(1.45, 1.65)
        camera = FollowPath((plan.lane_x, 0.0, z0), speed, Wave.random(rng, [0.05, 0.01], [3.0, 1.0 / step]),
                            Wave.random(rng, [0.1], [9.0]),
                            Wave.random(rng, [0.012, 0.004], [1.0 / step, 0.5 / step]),
                            None, h_aim, ratio,  # the subject follows: it passes abeam at the middle frame
                            (Wave.random(rng, [0.8 * DEG, 0.3 * DEG], [1.0 / step, 0.35]),
                             Wave.random(rng, [0.6 * DEG, 0.1 * DEG], [3.1, 0.4]),
                             Wave.random(rng, [1.0 * DEG, 0.1 * DEG], [4.1, 0.5])))
        k_mid = (cfg.frames - 1) / 2.0
        t_mid = k_mid / cfg.fps * cfg.camera_speed
        at = camera.position(t_mid)[1] + srng.uniform(-0.5, 0.5)
        x_s = plan.lane_x - srng.uniform(2.5, 4.5)
        subject = WeaveWalk((float(x_s), float(at)), (0.0, speed + srng.uniform(1.0, 1.3)),
                            k_mid / cfg.fps * cfg.mover_speed, weave=Wave.random(srng, [0.05], [4.0]),
                            surge=Wave.random(srng, [0.05], [3.0]), step_omega=step_omega)
        return FollowPath(camera.start, camera.speed, camera.surge, camera.lateral, camera.bob, subject, h_aim,
                          ratio, camera.shake)
    raise ValueError(f"unknown follow motion {cfg.motion!r} (use one of {', '.join(FOLLOW_MOTIONS)})")


def follow_world(cfg: SynthConfig) -> StreetWorld:
    """The street, the follow camera, the subject (mover 0) and the other movers of ``cfg``.

    The street runs from 10 m (``follow``; 35 m for ``follow-pan``, which looks back) behind the first
    camera position or subject, whichever is farther back, to 35 m beyond the last, a building across it at
    both ends.  Without movers (``static``) the camera still follows the subject's path: the same street and
    camera path, nobody in it.
    """
    seed = cfg.seed
    plan = street.street_plan(cfg.motion, seed)
    subject_parts = layout.walker_specs(seed, 0)
    camera = follow_path(cfg, plan, subject_parts)
    t = np.linspace(0.0, max(cfg.frames - 1, 1) / cfg.fps * cfg.camera_speed, 200)
    ys = np.concatenate([camera.position(t)[:, 1], camera.aim(t)[:, 1]])
    behind = 10.0 if cfg.motion == "follow" else plan.far
    y0, y_last = float(ys.min()) - behind, float(ys.max())
    y_end = y_last + plan.far
    statics = [*street_statics(plan, seed, y0, y_end, y_last), street.start_building(plan, seed, y0)]
    parts, paths = [], []
    roles = ROLES[cfg.motion]
    for i in range(cfg.n_movers):
        if i == 0:
            parts.append(subject_parts)
            paths.append(camera.subject)
            continue
        rng = np.random.default_rng([seed, TAG_MOVER, i])
        paths.append(mover_path(roles[(i - 1) % len(roles)], rng, cfg, plan, camera))
        parts.append(layout.walker_specs(seed, i))
    return StreetWorld(plan, camera, statics, parts, paths)
