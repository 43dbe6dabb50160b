"""A forward-motion world: the street, the travelling camera and the movers on it, with their paths.

Movers go in straight lines at constant speed (:class:`LineWalk`), each
given a role that a camera travelling down a street meets
(``SynthConfig.movers`` of them, roles taken in the order of the motion's list):

* ``oncoming``: a walker coming towards the camera on a line 0.8-1.4 m to
  its side, passing it at a random frame in the middle 30 % of the sequence;
* ``crossing``: a walker crossing the camera's line ahead of it (3-7 m on a
  walk, 8-15 m on a ride, 20-35 m on a drive) at a random frame;
* ``ahead``: a walker going the same way, slower, 1-2 m to the side,
  starting 8-14 m ahead: the camera catches up and passes;
* ``far``: a walker coming down the far sidewalk;
* ``car-oncoming``: a car in the other lane, 8-14 m/s, passing the camera;
* ``car-ahead``: a car in the camera's lane 18-30 m ahead, a little slower
  than the camera (it stays at least 8 m ahead).

Walker bodies are :func:`~droidw_cli.synth.layout.walker_specs`; cars
:func:`~droidw_cli.synth.street.car_parts`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.synth import layout, street
from droidw_cli.synth.config import SynthConfig
from droidw_cli.synth.forward import ForwardPath, forward_path
from droidw_cli.synth.layout import BoxSpec
from droidw_cli.synth.paths import rot_z

TAG_MOVER = 14
ROLES = {
    "forward": ("oncoming", "crossing", "ahead", "far"),
    "ride": ("crossing", "oncoming", "ahead", "far"),
    "drive": ("car-oncoming", "car-ahead", "crossing", "far"),
}
BEHIND = 10.0  # m of street behind the camera's start


@dataclass(frozen=True)
class LineWalk:
    """P(t) = P₀ + v (t − t₀) on the ground, facing v; walkers bob by ``bob`` at ``step_omega``/2π steps a second."""

    origin: tuple[float, float]
    velocity: tuple[float, float]
    t0: float
    bob: float = 0.0
    step_omega: float = 2 * np.pi * 1.8

    def state(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Body-to-world rotations (…, 3, 3) and body origins on the ground (…, 3), as EllipseWalk.state."""
        t = np.asarray(t, np.float64)
        xy = np.asarray(self.origin) + (t - self.t0)[..., None] * np.asarray(self.velocity)
        heading = np.full(t.shape, np.arctan2(self.velocity[1], self.velocity[0]))
        z = self.bob * np.abs(np.sin(0.5 * self.step_omega * t))
        return rot_z(heading - np.pi / 2), np.concatenate([xy, z[..., None]], -1)


@dataclass(frozen=True, eq=False)
class StreetWorld:
    """The street's boxes (the outer box first), the camera (a ForwardPath, or a
    :class:`~droidw_cli.synth.follow.FollowPath`), and each mover's parts and path."""

    plan: street.StreetPlan
    camera: ForwardPath
    statics: list[BoxSpec]
    mover_parts: list[list[BoxSpec]]
    paths: list[LineWalk]


def _walker(rng: np.random.Generator, at: np.ndarray, velocity: np.ndarray, t_at: float) -> LineWalk:
    return LineWalk((float(at[0]), float(at[1])), (float(velocity[0]), float(velocity[1])), float(t_at),
                    bob=0.015, step_omega=2 * np.pi * rng.uniform(1.6, 2.0))


def mover_path(role: str, rng: np.random.Generator, cfg: SynthConfig, plan: street.StreetPlan,
               camera: ForwardPath) -> LineWalk:
    """The path of one mover of ``role`` (module docstring), in walker time (camera and walker speeds apply)."""
    duration = cfg.frames / cfg.fps

    def cam_at(frac: float) -> tuple[np.ndarray, float]:  # the camera's floor position at that share of the run
        k = frac * (cfg.frames - 1)
        return camera.position(k / cfg.fps * cfg.camera_speed)[:2], k / cfg.fps * cfg.mover_speed

    side = float(rng.choice([-1.0, 1.0]))
    if role == "oncoming":
        at, t = cam_at(rng.uniform(0.35, 0.65))
        return _walker(rng, at + [side * rng.uniform(0.8, 1.4), 0.0], np.array([0.0, -rng.uniform(1.1, 1.5)]), t)
    if role == "crossing":
        ahead = {"forward": (3.0, 7.0), "ride": (8.0, 15.0), "drive": (20.0, 35.0), "follow": (5.0, 9.0),
                 "follow-pan": (3.0, 7.0)}[cfg.motion]
        at, t = cam_at(rng.uniform(0.2, 0.8))
        return _walker(rng, at + [0.0, rng.uniform(*ahead)], np.array([side * rng.uniform(1.0, 1.5), 0.0]), t)
    if role == "ahead":
        at, t = cam_at(0.0)
        return _walker(rng, at + [side * rng.uniform(1.0, 2.0), rng.uniform(8.0, 14.0)],
                       np.array([0.0, rng.uniform(0.55, 0.8) * camera.speed]), t)
    if role == "far":
        at, t = cam_at(rng.uniform(0.5, 1.0))
        x = -np.sign(plan.lane_x or 1.0) * (plan.road / 2 + plan.walk * rng.uniform(0.3, 0.7))
        return _walker(rng, np.array([x, at[1] + rng.uniform(2.0, 6.0)]), np.array([0.0, -rng.uniform(1.0, 1.4)]), t)
    if role == "car-oncoming":
        at, t = cam_at(rng.uniform(0.3, 0.7))
        return LineWalk((-plan.lane_x, float(at[1])), (0.0, -rng.uniform(8.0, 14.0)), float(t))
    if role == "car-ahead":
        at, t = cam_at(0.0)
        gap = rng.uniform(18.0, 30.0)
        slowest = max(0.0, camera.speed - (gap - 8.0) / duration)
        return LineWalk((plan.lane_x, float(at[1]) + gap), (0.0, rng.uniform(max(slowest, 0.85 * camera.speed),
                                                                                camera.speed)), float(t))
    raise ValueError(f"unknown mover role {role!r}")


def street_statics(plan: street.StreetPlan, seed: int, y0: float, y_end: float, y_last: float) -> list[BoxSpec]:
    """The street's boxes from y0 to its end y_end (the outer box first); y_last is the camera's farthest y."""
    return [street.outer_box(plan, seed, y0 - 2.0, y_end + 12.0),
            *street.ground_specs(plan, seed, y0, y_end, y_last),
            *street.building_specs(plan, seed, y0, y_end, y_last),
            *street.furnishing_specs(plan, seed, y0, y_end, y_last)]


def street_world(cfg: SynthConfig) -> StreetWorld:
    """Lay out the street of ``cfg`` (a forward motion), its camera path and movers."""
    seed = cfg.seed
    plan = street.street_plan(cfg.motion, seed)
    camera = forward_path(cfg.motion, np.random.default_rng([seed, layout.TAG_CAMERA, 20]), plan.lane_x)
    duration = max(cfg.frames - 1, 1) / cfg.fps * cfg.camera_speed
    ys = camera.position(np.linspace(0.0, duration, 200))[:, 1]
    y0, y_last = float(ys.min()) - BEHIND, float(ys.max())
    y_end = y_last + plan.far
    statics = street_statics(plan, seed, y0, y_end, y_last)
    roles = ROLES[cfg.motion]
    parts, paths = [], []
    for i in range(cfg.n_movers):
        role = roles[i] if i < len(roles) else roles[i % len(roles)]
        rng = np.random.default_rng([seed, TAG_MOVER, i])
        paths.append(mover_path(role, rng, cfg, plan, camera))
        parts.append(street.car_parts(seed, i) if role.startswith("car") else layout.walker_specs(seed, i))
    return StreetWorld(plan, camera, statics, parts, paths)
