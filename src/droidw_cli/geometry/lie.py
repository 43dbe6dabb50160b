"""SE(3) on pypose-layout tensors, batched and device-agnostic.

A pose is a (..., 7) tensor ``[tx, ty, tz, qx, qy, qz, qw]`` (pypose's SE3
layout, Hamilton quaternion, xyzw) acting on points as ``T·X = R(q) X + t``.
A twist is a (..., 6) tensor ``ξ = [v, ω]`` — translation part first, rotation
part last — which is pypose's se3 ordering, and

    Exp(ξ) = (R = exp([ω]×),  t = V(ω) v),
    V(ω)   = I + (1 − cos θ)/θ² [ω]× + (θ − sin θ)/θ³ [ω]×²,   θ = ‖ω‖,

so ``se3_exp(ξ)`` equals ``pypose.se3(ξ).Exp()`` (checked in the tests).
With left perturbations T ← Exp(ξ)·T a homogeneous point P = (X, W) moves by
δP = [W·v + ω × X, 0], and the adjoint in this ordering is

    Ad(T) = [[R, [t]× R],
             [0,      R ]],   Exp(Ad(T) ξ) = T Exp(ξ) T⁻¹.

These few functions are written out (instead of calling pypose) so that the
BA's hot path stays plain tensor arithmetic that also runs inside the CUDA
backend's torch glue.
"""

from __future__ import annotations

import torch
from torch import Tensor

#: below this rotation angle (rad) the Exp map uses its Taylor expansion
SMALL_ANGLE = 1e-4


def quat_to_matrix(q: Tensor) -> Tensor:
    """Rotation matrices (..., 3, 3) of unit quaternions (..., 4) in xyzw order."""
    x, y, z, w = q.unbind(-1)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    rows = (
        1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
        2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
        2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
    )
    return torch.stack(rows, dim=-1).reshape(q.shape[:-1] + (3, 3))


def quat_multiply(a: Tensor, b: Tensor) -> Tensor:
    """Hamilton product a ⊗ b of xyzw quaternions (rotation b first, then a)."""
    ax, ay, az, aw = a.unbind(-1)
    bx, by, bz, bw = b.unbind(-1)
    return torch.stack((
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ), dim=-1)


def quat_conjugate(q: Tensor) -> Tensor:
    """The inverse rotation of a unit quaternion (xyzw)."""
    return torch.cat((-q[..., :3], q[..., 3:]), dim=-1)


def quat_rotate(q: Tensor, x: Tensor) -> Tensor:
    """R(q) x for quaternions (..., 4) and vectors (..., 3)."""
    qv, qw = q[..., :3], q[..., 3:]
    t = 2.0 * torch.cross(qv, x, dim=-1)
    return x + qw * t + torch.cross(qv, t, dim=-1)


def pose_inverse(T: Tensor) -> Tensor:
    """T⁻¹ = (Rᵀ, −Rᵀ t) for poses (..., 7)."""
    qi = quat_conjugate(T[..., 3:])
    return torch.cat((-quat_rotate(qi, T[..., :3]), qi), dim=-1)


def pose_compose(a: Tensor, b: Tensor) -> Tensor:
    """a·b (apply b, then a): (R_a R_b, R_a t_b + t_a)."""
    t = quat_rotate(a[..., 3:], b[..., :3]) + a[..., :3]
    return torch.cat((t, quat_multiply(a[..., 3:], b[..., 3:])), dim=-1)


def pose_act(T: Tensor, x: Tensor) -> Tensor:
    """T·x = R x + t for poses (..., 7) and points (..., 3)."""
    return quat_rotate(T[..., 3:], x) + T[..., :3]


def pose_matrix(T: Tensor) -> tuple[Tensor, Tensor]:
    """(R (..., 3, 3), t (..., 3)) of poses (..., 7)."""
    return quat_to_matrix(T[..., 3:]), T[..., :3]


def skew(w: Tensor) -> Tensor:
    """[w]× (..., 3, 3), so that [w]× x = w × x."""
    x, y, z = w.unbind(-1)
    o = torch.zeros_like(x)
    return torch.stack((o, -z, y, z, o, -x, -y, x, o), dim=-1).reshape(w.shape[:-1] + (3, 3))


def _angle(w: Tensor) -> tuple[Tensor, Tensor, Tensor]:
    """(θ², a safe θ (1 where small), small mask) with finite gradients at θ = 0."""
    theta2 = (w * w).sum(-1, keepdim=True)
    small = theta2 < SMALL_ANGLE * SMALL_ANGLE
    safe = torch.where(small, torch.ones_like(theta2), theta2).sqrt()
    return theta2, safe, small


def so3_exp_quat(w: Tensor) -> Tensor:
    """Unit quaternion (xyzw) of the rotation vector w (..., 3)."""
    theta2, safe, small = _angle(w)
    # sin(θ/2)/θ and cos(θ/2), with their Taylor series near 0
    k = torch.where(small, 0.5 - theta2 / 48.0, torch.sin(0.5 * safe) / safe)
    c = torch.where(small, 1.0 - theta2 / 8.0, torch.cos(0.5 * safe))
    return torch.cat((k * w, c), dim=-1)


def se3_exp(xi: Tensor) -> Tensor:
    """Exp of twists ξ = [v, ω] (..., 6) as poses (..., 7); equals pypose's se3 Exp."""
    v, w = xi[..., :3], xi[..., 3:]
    theta2, safe, small = _angle(w)
    # V v = v + a (ω × v) + b ω × (ω × v) with a = (1 − cos θ)/θ², b = (θ − sin θ)/θ³
    a = torch.where(small, 0.5 - theta2 / 24.0, (1.0 - torch.cos(safe)) / (safe * safe))
    b = torch.where(small, 1.0 / 6.0 - theta2 / 120.0, (safe - torch.sin(safe)) / (safe * safe * safe))
    wxv = torch.cross(w, v, dim=-1)
    t = v + a * wxv + b * torch.cross(w, wxv, dim=-1)
    return torch.cat((t, so3_exp_quat(w)), dim=-1)


def so3_log_quat(q: Tensor) -> Tensor:
    """Rotation vector ω (..., 3) of unit quaternions (..., 4), xyzw, with θ = ‖ω‖ ≤ π.

    q and −q are the same rotation: with w ≥ 0, θ = 2 atan2(‖q_v‖, w) and
    ω = θ/‖q_v‖ · q_v (→ 2 q_v / w as ‖q_v‖ → 0).
    """
    sign = torch.where(q[..., 3:] < 0, -torch.ones_like(q[..., 3:]), torch.ones_like(q[..., 3:]))
    qv, w = sign * q[..., :3], sign * q[..., 3:]
    n = qv.norm(dim=-1, keepdim=True)
    tiny = n < 1e-12
    safe = torch.where(tiny, torch.ones_like(n), n)
    factor = torch.where(tiny, 2.0 / w, 2.0 * torch.atan2(safe, w) / safe)
    return factor * qv


def se3_log(T: Tensor) -> Tensor:
    """Log of poses (..., 7) as twists ξ = [v, ω] (..., 6), the inverse of :func:`se3_exp`; equals pypose's SE3 Log.

    ω from the quaternion (:func:`so3_log_quat`), v = V(ω)⁻¹ t with

        V⁻¹ = I − ½ [ω]× + c [ω]×²,   c = (1 − (θ/2) cot(θ/2)) / θ²   (→ 1/12 + θ²/720 at θ → 0).
    """
    w = so3_log_quat(T[..., 3:])
    theta2 = (w * w).sum(-1, keepdim=True)
    small = theta2 < 1e-4
    safe2 = torch.where(small, torch.ones_like(theta2), theta2)
    half = 0.5 * safe2.sqrt()
    c = torch.where(small, 1.0 / 12.0 + theta2 / 720.0, (1.0 - half * torch.cos(half) / torch.sin(half)) / safe2)
    t = T[..., :3]
    wxt = torch.cross(w, t, dim=-1)
    v = t - 0.5 * wxt + c * torch.cross(w, wxt, dim=-1)
    return torch.cat((v, w), dim=-1)


def adjoint_matrix(R: Tensor, t: Tensor) -> Tensor:
    """Ad(T) (..., 6, 6) in the [v, ω] ordering from R (..., 3, 3) and t (..., 3)."""
    top = torch.cat((R, skew(t) @ R), dim=-1)
    bottom = torch.cat((torch.zeros_like(R), R), dim=-1)
    return torch.cat((top, bottom), dim=-2)


def rotation_angle(q: Tensor) -> Tensor:
    """Angle (rad) of the rotations given as unit quaternions (..., 4)."""
    return 2.0 * torch.atan2(q[..., :3].norm(dim=-1), q[..., 3].abs())


def pose_distance(a: Tensor, b: Tensor) -> tuple[Tensor, Tensor]:
    """(translation error, rotation error in rad) of a·b⁻¹ for poses (..., 7)."""
    d = pose_compose(a, pose_inverse(b))
    return d[..., :3].norm(dim=-1), rotation_angle(d[..., 3:])


def normalize_pose(T: Tensor) -> Tensor:
    """The pose with its quaternion renormalised to unit length."""
    return torch.cat((T[..., :3], T[..., 3:] / T[..., 3:].norm(dim=-1, keepdim=True)), dim=-1)
