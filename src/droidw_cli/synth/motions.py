"""Camera path families (``SynthConfig.motion``): all smooth, exact, and drawn from the seed.

Every path offers, vectorised over the time t (seconds, scalar or array):

* ``position(t)`` (…, 3) the camera centre in the world;
* ``rotation(t)`` (…, 3, 3) camera-to-world, columns (right, down, forward);
* ``target(t)`` (…, 3) a point the camera looks (roughly) towards — the
  walkers' tuning lays walker 0's crossing along it;
* ``pose(t)`` (…, 4, 4) camera-to-world.

Families (R_lookat(p, L) is :func:`~droidw_cli.synth.paths.look_at`; waves
are sums of sines Σᵢ aᵢ sin(ωᵢ t + φᵢ) with random phases, see
:class:`~droidw_cli.synth.paths.Wave`):

``handheld``  :class:`~droidw_cli.synth.paths.CameraPath`, unchanged: a
    room-scale sway (about a metre) with a drifting look-at target.

``wobble``  a near-still hand:  p(t) = p₀ + s(t) with per-axis waves of a
    centimetre or two plus a millimetre of tremor (periods 0.25-0.4 s), and
    R(t) = R_lookat(p(t), L) · R_z(roll) R_x(pitch) R_y(yaw) with a fixed target
    L and wobble waves of 2-3° amplitude per axis: about 6 cm and 7° peak to peak.

``rotate``  fast rotation on the spot:  p(t) = c + s(t) (±5 cm per axis) and

        R(t) = R_z(ψ(t)) · R₀ · R_x(θ(t)) · R_z(φ(t)),   R₀ = R_lookat(c, L₀),

    a pan ψ about the world's vertical (±35-45°, period ≈ 3.6 s), then a tilt
    θ about the camera's x axis and a roll φ about its optical axis (±~15°,
    periods ≈ 3 s): peaks of 60-90°/s.  The camera stays more than a metre
    from the walls, floor and ceiling in every direction it can look.
    target(t) = p(t) + 2.5 m · (optical axis).

``stopgo``  the handheld path at warped time, pose(t) = P_handheld(τ(t)), with
    τ(t) = F(t + φ) − F(φ), F(x) = ∫₀ˣ v, where the speed v ≥ 0 is periodic
    (period T ≈ 5 s): a raised-cosine ramp up over r seconds, 1 while moving,
    a ramp down, then 0 for a stop of S ≈ 1.5-2 s.  With u = x mod T, M = T − S:

        G(u) = (u − (r/π) sin(πu/r)) / 2                       u < r
               r/2 + (u − r)                                   r ≤ u < M − r
               M − 3r/2 + (w + (r/π) sin(πw/r)) / 2,  w = u − M + r     M − r ≤ u < M
               M − r                                           u ≥ M

    and F(x) = ⌊x/T⌋ (M − r) + G(u).  v is C¹ (zero slope at the ramp ends),
    so the motion eases in and out; during a stop τ is exactly constant, so
    the poses repeat bit for bit.  Moving, the camera has the handheld speed.

``fixed``  one pose for every frame (computed once and broadcast, so
    bit-identical), looking down into the room where the walkers pass.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from droidw_cli.synth import layout
from droidw_cli.synth.config import MOTIONS
from droidw_cli.synth.paths import CameraPath, Wave, look_at, random_camera_path, rot_x, rot_y, rot_z

DEG = np.pi / 180.0


class CameraMotion(Protocol):
    """What the scene needs of a camera path (every method vectorised over t, in seconds)."""

    def position(self, t) -> np.ndarray: ...

    def target(self, t) -> np.ndarray: ...

    def rotation(self, t) -> np.ndarray: ...

    def pose(self, t) -> np.ndarray: ...


def compose_pose(rotation: np.ndarray, position: np.ndarray) -> np.ndarray:
    """(…, 4, 4) camera-to-world poses from (…, 3, 3) rotations and (…, 3) positions."""
    out = np.zeros(position.shape[:-1] + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = position
    out[..., 3, 3] = 1.0
    return out


def _waves(t, waves) -> np.ndarray:
    return np.stack([w(t) for w in waves], -1)


def _broadcast(value: np.ndarray, t) -> np.ndarray:
    """``value`` repeated over the shape of t (a copy: bit-identical entries)."""
    shape = np.shape(t)
    return np.array(np.broadcast_to(value, shape + value.shape))


@dataclass(frozen=True)
class WobblePath:
    """A near-still hand: centimetres of drift and tremor, a few degrees of wobble (radians) about a fixed target."""

    base: tuple[float, float, float]
    drift: tuple[Wave, Wave, Wave]
    look: tuple[float, float, float]
    wobble: tuple[Wave, Wave, Wave]  # roll, pitch, yaw

    def position(self, t) -> np.ndarray:
        return np.asarray(self.base) + _waves(t, self.drift)

    def target(self, t) -> np.ndarray:
        return _broadcast(np.asarray(self.look, np.float64), t)

    def rotation(self, t) -> np.ndarray:
        roll, pitch, yaw = (w(t) for w in self.wobble)
        return look_at(self.position(t), self.target(t)) @ rot_z(roll) @ rot_x(pitch) @ rot_y(yaw)

    def pose(self, t) -> np.ndarray:
        return compose_pose(self.rotation(t), self.position(t))


@dataclass(frozen=True)
class RotatePath:
    """Fast pan ψ, tilt θ and roll φ (radians) about a base view R₀ = R_lookat(centre, look), a small sway."""

    centre: tuple[float, float, float]
    sway: tuple[Wave, Wave, Wave]
    look: tuple[float, float, float]
    angles: tuple[Wave, Wave, Wave]  # pan (world vertical), tilt (camera x), roll (optical axis)
    reach: float = 2.5

    def position(self, t) -> np.ndarray:
        return np.asarray(self.centre) + _waves(t, self.sway)

    def rotation(self, t) -> np.ndarray:
        pan, tilt, roll = (w(t) for w in self.angles)
        base = look_at(np.asarray(self.centre, np.float64), np.asarray(self.look, np.float64))
        return rot_z(pan) @ base @ rot_x(tilt) @ rot_z(roll)

    def target(self, t) -> np.ndarray:
        return self.position(t) + self.reach * self.rotation(t)[..., :, 2]

    def pose(self, t) -> np.ndarray:
        return compose_pose(self.rotation(t), self.position(t))


@dataclass(frozen=True)
class StopGoWarp:
    """The monotone time warp τ(t) = F(t + phase) − F(phase) of the module docstring (seconds)."""

    period: float
    stop: float
    ramp: float
    phase: float

    def _cumulative(self, x: np.ndarray) -> np.ndarray:
        big_t, r = self.period, self.ramp
        m = big_t - self.stop
        n = np.floor(x / big_t)
        u = x - n * big_t
        w = u - (m - r)
        k = np.pi / r
        g = np.where(u < r, 0.5 * (u - np.sin(k * u) / k),
                     np.where(u < m - r, 0.5 * r + (u - r),
                              np.where(u < m, m - 1.5 * r + 0.5 * (w + np.sin(k * w) / k), m - r)))
        return n * (m - r) + g

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)
        return self._cumulative(t + self.phase) - self._cumulative(np.float64(self.phase))

    def speed(self, t) -> np.ndarray:
        """dτ/dt ∈ [0, 1]."""
        r, m = self.ramp, self.period - self.stop
        u = np.mod(np.asarray(t, np.float64) + self.phase, self.period)
        return np.where(u < r, 0.5 * (1 - np.cos(np.pi * u / r)),
                        np.where(u < m - r, 1.0, np.where(u < m, 0.5 * (1 + np.cos(np.pi * (u - m + r) / r)), 0.0)))


@dataclass(frozen=True)
class StopGoPath:
    """A path (the handheld one) followed at warped time: it stops and starts again."""

    path: CameraPath
    warp: StopGoWarp

    def position(self, t) -> np.ndarray:
        return self.path.position(self.warp(t))

    def target(self, t) -> np.ndarray:
        return self.path.target(self.warp(t))

    def rotation(self, t) -> np.ndarray:
        return self.path.rotation(self.warp(t))

    def pose(self, t) -> np.ndarray:
        return self.path.pose(self.warp(t))


@dataclass(frozen=True)
class FixedPath:
    """A camera that does not move."""

    eye: tuple[float, float, float]
    look: tuple[float, float, float]

    def position(self, t) -> np.ndarray:
        return _broadcast(np.asarray(self.eye, np.float64), t)

    def target(self, t) -> np.ndarray:
        return _broadcast(np.asarray(self.look, np.float64), t)

    def rotation(self, t) -> np.ndarray:
        return _broadcast(look_at(np.asarray(self.eye, np.float64), np.asarray(self.look, np.float64)), t)

    def pose(self, t) -> np.ndarray:
        return _broadcast(compose_pose(self.rotation(0.0), self.position(0.0)), t)


def wobble_path(rng: np.random.Generator, room: np.ndarray) -> WobblePath:
    wid, dep, _ = room
    base = (rng.uniform(-0.5, 0.5), rng.uniform(0.8, 1.1), rng.uniform(1.35, 1.55))
    drift = (
        Wave.random(rng, [0.020, 0.007, 0.001], [7.5, 2.6, 0.31]),
        Wave.random(rng, [0.014, 0.005, 0.001], [9.0, 3.1, 0.27]),
        Wave.random(rng, [0.011, 0.005, 0.001], [6.1, 2.2, 0.35]),
    )
    look = (rng.uniform(-0.1, 0.1) * wid, dep - rng.uniform(1.1, 1.5), rng.uniform(0.9, 1.2))
    wobble = (
        Wave.random(rng, [1.4 * DEG, 0.45 * DEG, 0.06 * DEG], [5.3, 1.9, 0.29]),
        Wave.random(rng, [1.9 * DEG, 0.6 * DEG, 0.06 * DEG], [4.1, 1.6, 0.33]),
        Wave.random(rng, [2.4 * DEG, 0.75 * DEG, 0.06 * DEG], [6.7, 2.3, 0.37]),
    )
    return WobblePath(base, drift, look, wobble)


def rotate_path(rng: np.random.Generator, room: np.ndarray) -> RotatePath:
    _, dep, _ = room
    centre = (rng.uniform(-0.3, 0.3), rng.uniform(1.0, 1.3), rng.uniform(1.35, 1.5))
    sway = tuple(Wave.random(rng, [0.04, 0.01], [4.5, 1.6]) for _ in range(3))
    look = (rng.uniform(-0.3, 0.3), dep - 1.0, rng.uniform(1.0, 1.2))
    angles = (
        Wave.random(rng, [rng.uniform(35.0, 42.0) * DEG, 3.0 * DEG], [3.6, 1.7]),
        Wave.random(rng, [12.0 * DEG, 2.5 * DEG], [2.9, 1.3]),
        Wave.random(rng, [12.0 * DEG, 2.5 * DEG], [3.3, 1.5]),
    )
    return RotatePath(centre, sway, look, angles)  # type: ignore[arg-type]


def stopgo_warp(rng: np.random.Generator) -> StopGoWarp:
    period, stop, ramp = rng.uniform(4.6, 5.4), rng.uniform(1.5, 2.0), rng.uniform(0.6, 0.9)
    moving = period - stop
    phase = rng.uniform(ramp, moving - ramp - 0.4)  # start in the middle of a motion
    return StopGoWarp(float(period), float(stop), float(ramp), float(phase))


def fixed_path(rng: np.random.Generator, room: np.ndarray) -> FixedPath:
    _, dep, _ = room
    eye = (rng.uniform(-0.5, 0.5), rng.uniform(0.5, 0.8), rng.uniform(1.45, 1.7))
    look = (rng.uniform(-0.4, 0.4), dep - rng.uniform(1.4, 1.8), rng.uniform(0.8, 1.0))
    return FixedPath(eye, look)


def camera_motion(motion: str, seed: int, room: np.ndarray) -> CameraMotion:
    """The camera path of family ``motion`` for ``seed`` in a room [width, depth, height].

    ``handheld`` draws from the same stream as before (identical paths);
    ``stopgo`` warps that same handheld path; the others use their own streams.
    """
    if motion not in MOTIONS:
        raise ValueError(f"unknown motion {motion!r} (use one of {', '.join(MOTIONS)})")
    if motion in ("handheld", "stopgo"):
        path = random_camera_path(np.random.default_rng([seed, layout.TAG_CAMERA]), room)
        if motion == "handheld":
            return path
        return StopGoPath(path, stopgo_warp(np.random.default_rng([seed, layout.TAG_CAMERA, 1])))
    rng = np.random.default_rng([seed, layout.TAG_CAMERA, 1 + MOTIONS.index(motion)])
    return {"wobble": wobble_path, "rotate": rotate_path, "fixed": fixed_path}[motion](rng, room)
