"""Smooth motions: the handheld camera path and the walkers' loops.

All functions take a time (seconds, scalar or array) and are vectorised over it.

Camera.  Position p(t) = p₀ + Σᵢ aᵢ sin(ωᵢ t + φᵢ) per axis (slow sway of
about a metre plus a few centimetres of hand bob); the camera looks at a
target L(t) that itself drifts along the far part of the room, so the view
pans across the walls.  A small wobble (roll, pitch, yaw of a few degrees,
again sums of sines) is applied in the camera frame:

    R_c2w(t) = R_lookat(p(t), L(t)) · R_z(roll) · R_x(pitch) · R_y(yaw)

where R_lookat has columns (right, down, forward) — the OpenCV camera axes.

Walkers.  A walker moves along an ellipse on the floor,

    P(s) = C + a cos(s) e₁ + b sin(s) e₂,   s(t) = s₀ + ω t,

facing its direction of travel sign(ω)·dP/ds, with a small vertical bob at
step frequency.  The body frame has x across the shoulders, y forward and
z up, so R_body = R_z(θ − π/2) with θ the heading angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

UP = np.array([0.0, 0.0, 1.0])


def rot_x(a) -> np.ndarray:
    a = np.asarray(a, np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def rot_y(a) -> np.ndarray:
    a = np.asarray(a, np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def rot_z(a) -> np.ndarray:
    a = np.asarray(a, np.float64)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def look_at(pos: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Camera-to-world rotations (…, 3, 3) with columns (right, down, forward), z-up world."""
    f = target - pos
    f = f / np.linalg.norm(f, axis=-1, keepdims=True)
    r = np.cross(f, UP)
    r = r / np.linalg.norm(r, axis=-1, keepdims=True)
    d = np.cross(f, r)
    return np.stack([r, d, f], -1)


@dataclass(frozen=True)
class Wave:
    """f(t) = Σᵢ aᵢ sin(ωᵢ t + φᵢ)."""

    amp: tuple[float, ...]
    omega: tuple[float, ...]
    phase: tuple[float, ...]

    def __call__(self, t) -> np.ndarray:
        t = np.asarray(t, np.float64)[..., None]
        return (np.asarray(self.amp) * np.sin(np.asarray(self.omega) * t + np.asarray(self.phase))).sum(-1)

    def rate(self, t) -> np.ndarray:
        """df/dt = Σᵢ aᵢ ωᵢ cos(ωᵢ t + φᵢ)."""
        t = np.asarray(t, np.float64)[..., None]
        omega = np.asarray(self.omega)
        return (np.asarray(self.amp) * omega * np.cos(omega * t + np.asarray(self.phase))).sum(-1)

    @staticmethod
    def random(rng: np.random.Generator, amps, periods) -> "Wave":
        """Random phases; periods (seconds) jittered by ±15 %."""
        periods = np.asarray(periods, np.float64) * rng.uniform(0.85, 1.15, len(periods))
        phase = rng.uniform(0.0, 2 * np.pi, len(periods))
        return Wave(tuple(float(a) for a in amps), tuple(float(w) for w in 2 * np.pi / periods), tuple(phase.tolist()))


@dataclass(frozen=True)
class CameraPath:
    """A handheld camera: swaying position, drifting look-at target, small wobble (radians)."""

    base: tuple[float, float, float]
    sway: tuple[Wave, Wave, Wave]
    target_base: tuple[float, float, float]
    target_sway: tuple[Wave, Wave, Wave]
    wobble: tuple[Wave, Wave, Wave]  # roll, pitch, yaw

    def position(self, t) -> np.ndarray:
        return np.asarray(self.base) + np.stack([w(t) for w in self.sway], -1)

    def target(self, t) -> np.ndarray:
        return np.asarray(self.target_base) + np.stack([w(t) for w in self.target_sway], -1)

    def rotation(self, t) -> np.ndarray:
        roll, pitch, yaw = (w(t) for w in self.wobble)
        return look_at(self.position(t), self.target(t)) @ rot_z(roll) @ rot_x(pitch) @ rot_y(yaw)

    def pose(self, t) -> np.ndarray:
        """Camera-to-world 4×4 pose(s), shape (…, 4, 4)."""
        t = np.asarray(t, np.float64)
        out = np.zeros(t.shape + (4, 4))
        out[..., :3, :3] = self.rotation(t)
        out[..., :3, 3] = self.position(t)
        out[..., 3, 3] = 1.0
        return out


def random_camera_path(rng: np.random.Generator, room: np.ndarray) -> CameraPath:
    """A camera near the back of the room, looking into it (room = [width, depth, height])."""
    wid, dep, hei = room
    base = (0.0, 1.0, 1.45)
    sway = (
        Wave.random(rng, [0.9, 0.25, 0.012], [14.0, 5.3, 0.9]),
        Wave.random(rng, [0.35, 0.08, 0.010], [10.0, 3.7, 1.1]),
        Wave.random(rng, [0.06, 0.015, 0.006], [6.5, 1.9, 0.8]),
    )
    target_base = (0.0, dep - 1.2, 1.05)
    target_sway = (
        Wave.random(rng, [0.3 * wid, 0.06 * wid], [17.0, 6.8]),
        Wave.random(rng, [0.5, 0.15], [12.0, 5.0]),
        Wave.random(rng, [0.2, 0.05], [9.0, 3.3]),
    )
    deg = np.pi / 180.0
    wobble = (
        Wave.random(rng, [2.0 * deg, 0.6 * deg, 0.15 * deg], [3.7, 1.3, 0.45]),
        Wave.random(rng, [1.5 * deg, 0.5 * deg, 0.15 * deg], [2.9, 1.1, 0.5]),
        Wave.random(rng, [1.5 * deg, 0.4 * deg, 0.15 * deg], [4.3, 1.5, 0.55]),
    )
    return CameraPath(base, sway, target_base, target_sway, wobble)


@dataclass(frozen=True)
class EllipseWalk:
    """A walker on the ellipse C + a cos(s) e₁ + b sin(s) e₂, s = s₀ + ω t (e₂ ⟂ e₁, both on the floor)."""

    centre: tuple[float, float]
    e1: tuple[float, float]
    a: float
    b: float
    omega: float
    s0: float
    bob: float = 0.015
    step_omega: float = 2 * np.pi * 1.8

    def state(self, t) -> tuple[np.ndarray, np.ndarray]:
        """Body-to-world rotations (…, 3, 3) and positions of the body origin on the floor (…, 3)."""
        t = np.asarray(t, np.float64)
        s = self.s0 + self.omega * t
        e1 = np.asarray(self.e1)
        e2 = np.array([-e1[1], e1[0]])
        xy = np.asarray(self.centre) + (self.a * np.cos(s))[..., None] * e1 + (self.b * np.sin(s))[..., None] * e2
        vel = np.sign(self.omega) * ((-self.a * np.sin(s))[..., None] * e1 + (self.b * np.cos(s))[..., None] * e2)
        heading = np.arctan2(vel[..., 1], vel[..., 0])
        z = self.bob * np.abs(np.sin(0.5 * self.step_omega * t + self.s0))
        return rot_z(heading - np.pi / 2), np.concatenate([xy, z[..., None]], -1)


def make_walk(centre, e1, a: float, b: float, speed: float, direction: int, s_at: float, t_at: float) -> EllipseWalk:
    """An ellipse walk at mean speed ``speed`` (m/s) that is at parameter ``s_at`` at time ``t_at``.

    Mean speed ≈ |ω|·√((a² + b²)/2) (the ellipse's mean radius).
    """
    omega = direction * speed / np.sqrt(0.5 * (a * a + b * b))
    return EllipseWalk(tuple(float(v) for v in centre), tuple(float(v) for v in e1), float(a), float(b),
                       float(omega), float(s_at - omega * t_at))
