"""Camera paths that travel into the scene: a walk, a ride and a drive down a street (+y).

Every path offers the :class:`~droidw_cli.synth.motions.CameraMotion` methods,
vectorised over t (seconds).  With waves W (sums of sines with random phases,
:class:`~droidw_cli.synth.paths.Wave`):

    p(t) = (x₀ + W_lat(t),  y₀ + v t + W_surge(t),  z₀ + W_bob(t))
    ψ(t) = f · atan(ẋ / ẏ) + W_yaw(t)          heading: f of the path's own turn, plus looking around
    R(t) = R_lookat(p, p + (sin ψ, cos ψ, 0)) · R_x(−τ) · R_z(W_roll) · R_x(W_pitch) · R_y(W_shake)

τ is a fixed downward tilt.  ``walk`` (1.2-1.6 m/s, a hand-held phone at
1.45-1.65 m): step bob of 2-3 cm at 1.7-2.1 steps per second, half-step
sway, 0.3-0.5 m of meander, the heading following it by half and looking
around by ±4°, hand shake of about 1° at 1-3 Hz.  ``ride`` (4-6 m/s, a bike
at 1.3-1.5 m): a smooth weave of 1-1.6 m over 8-11 s that the heading follows
(about ±10° of yaw), road vibration of a few millimetres.  ``drive``
(8-15 m/s, a car camera at 1.65 m as on KITTI's car, level): a lane drift of
0.2-0.4 m, a centimetre of suspension, tenths of a degree of vibration.

``target(t)`` is the point 10 m ahead along the optical axis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.synth.config import FORWARD_MOTIONS
from droidw_cli.synth.motions import DEG, compose_pose
from droidw_cli.synth.paths import Wave, look_at, rot_x, rot_y, rot_z


@dataclass(frozen=True)
class ForwardPath:
    """A camera travelling along +y (module docstring); angles in radians."""

    start: tuple[float, float, float]
    speed: float
    surge: Wave
    lateral: Wave
    bob: Wave
    tilt: float
    follow: float
    yaw: Wave
    shake: tuple[Wave, Wave, Wave]  # roll, pitch, yaw about the camera axes

    def position(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)
        x0, y0, z0 = self.start
        return np.stack([x0 + self.lateral(t), y0 + self.speed * t + self.surge(t), z0 + self.bob(t)], -1)

    def heading(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)
        turn = np.arctan2(self.lateral.rate(t), self.speed + self.surge.rate(t))
        return self.follow * turn + self.yaw(t)

    def rotation(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)
        p = self.position(t)
        psi = self.heading(t)
        ahead = np.stack([np.sin(psi), np.cos(psi), np.zeros_like(psi)], -1)
        roll, pitch, yaw = (w(t) for w in self.shake)
        return look_at(p, p + ahead) @ rot_x(np.full_like(t, -self.tilt)) @ rot_z(roll) @ rot_x(pitch) @ rot_y(yaw)

    def target(self, t) -> np.ndarray:
        return self.position(t) + 10.0 * self.rotation(t)[..., :, 2]

    def pose(self, t) -> np.ndarray:
        return compose_pose(self.rotation(t), self.position(t))


def forward_path(motion: str, rng: np.random.Generator, lane_x: float) -> ForwardPath:
    """The path of family ``motion`` (:data:`FORWARD_MOTIONS`) starting at y = 0 on the line x = ``lane_x``."""
    if motion == "forward":
        speed = rng.uniform(1.2, 1.6)
        step = rng.uniform(1.7, 2.1)  # steps per second: the bob's frequency; the sway has half of it
        return ForwardPath(
            start=(lane_x, 0.0, rng.uniform(1.45, 1.65)), speed=speed,
            surge=Wave.random(rng, [0.03, 0.01], [1.0 / step, 4.0]),
            lateral=Wave.random(rng, [rng.uniform(0.3, 0.5), 0.012], [13.0, 2.0 / step]),
            bob=Wave.random(rng, [rng.uniform(0.02, 0.03), 0.006], [1.0 / step, 0.5 / step]),
            tilt=rng.uniform(2.0, 6.0) * DEG, follow=0.5,
            yaw=Wave.random(rng, [4.0 * DEG, 1.5 * DEG], [7.0, 3.1]),
            shake=(Wave.random(rng, [1.0 * DEG, 0.3 * DEG], [1.0 / step, 0.35]),
                   Wave.random(rng, [0.8 * DEG, 0.3 * DEG], [0.5 / step, 0.4]),
                   Wave.random(rng, [0.7 * DEG, 0.2 * DEG], [2.0 / step, 0.45])))
    if motion == "ride":
        return ForwardPath(
            start=(lane_x, 0.0, rng.uniform(1.3, 1.5)), speed=rng.uniform(4.0, 6.0),
            surge=Wave.random(rng, [0.15], [5.0]),
            lateral=Wave.random(rng, [rng.uniform(1.0, 1.6), 0.05], [rng.uniform(8.0, 11.0), 1.3]),
            bob=Wave.random(rng, [0.006, 0.003], [0.31, 0.13]),
            tilt=rng.uniform(3.0, 7.0) * DEG, follow=1.0,
            yaw=Wave.random(rng, [2.0 * DEG], [4.3]),
            shake=(Wave.random(rng, [0.6 * DEG, 0.15 * DEG], [2.1, 0.21]),
                   Wave.random(rng, [0.3 * DEG, 0.15 * DEG], [1.7, 0.17]),
                   Wave.random(rng, [0.3 * DEG, 0.1 * DEG], [2.5, 0.23])))
    if motion == "drive":
        return ForwardPath(
            start=(lane_x, 0.0, 1.65), speed=rng.uniform(8.0, 15.0),
            surge=Wave.random(rng, [0.4], [6.0]),
            lateral=Wave.random(rng, [rng.uniform(0.2, 0.4)], [rng.uniform(12.0, 16.0)]),
            bob=Wave.random(rng, [0.008, 0.003], [0.8, 0.27]),
            tilt=0.0, follow=1.0,
            yaw=Wave.random(rng, [0.5 * DEG], [5.0]),
            shake=(Wave.random(rng, [0.15 * DEG, 0.05 * DEG], [1.1, 0.3]),
                   Wave.random(rng, [0.2 * DEG, 0.05 * DEG], [0.9, 0.25]),
                   Wave.random(rng, [0.1 * DEG], [1.3])))
    raise ValueError(f"unknown forward motion {motion!r} (use one of {', '.join(FORWARD_MOTIONS)})")
