"""Umeyama alignment of point sets: Sim(3), SE(3) or none.

Given matched positions ``x_i`` (estimate) and ``y_i`` (ground truth),
``i = 1..n``, find ``c, R, t`` minimising ``Σ ||y_i - (c R x_i + t)||²``
(Umeyama 1991, PAMI 13(4)):

    μx = mean(x),  μy = mean(y),  σx² = (1/n) Σ ||x_i - μx||²
    Σxy = (1/n) Σ (y_i - μy)(x_i - μx)ᵀ = U D Vᵀ              (SVD)
    S = diag(1, 1, sign(det U · det V))                     (reflection fix)
    R = U S Vᵀ,   c = tr(D S) / σx²   (c = 1 for SE(3)),   t = μy - c R μx

Without the reflection fix, a mirrored point set would produce det R = -1.
Aligned poses: ``T' = [R R_i | c R t_i + t]`` (the estimate's scale changes,
its orientations are only rotated).

Degenerate inputs raise :class:`DegenerateGeometryError`: the rotation is
undetermined when either point set is collinear (second singular value of
its centred covariance ≈ 0) or a single point (first one ≈ 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from droidw_cli.errors import InputError

ALIGN_MODES = ("sim3", "se3", "none")

# Relative threshold on the covariance singular values (variances, m²):
# s2 / s1 below it means "collinear" (a lateral spread under 1e-5 of the main one).
COLLINEAR_RTOL = 1e-10
# Absolute threshold for "all identical", relative to the coordinate magnitude.
IDENTICAL_RTOL = 1e-9


class DegenerateGeometryError(InputError):
    """The matched positions do not determine an alignment (identical or collinear)."""


@dataclass(frozen=True, eq=False)
class Sim3:
    """``x ↦ scale · rotation @ x + translation``."""

    rotation: np.ndarray
    translation: np.ndarray
    scale: float = 1.0

    @staticmethod
    def identity() -> "Sim3":
        return Sim3(np.eye(3), np.zeros(3), 1.0)

    def apply_points(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) → (N, 3)."""
        return self.scale * np.asarray(points, dtype=np.float64) @ self.rotation.T + self.translation

    def apply_poses(self, poses: np.ndarray) -> np.ndarray:
        """(N, 4, 4) camera-to-world poses → aligned poses ``[R R_i | c R t_i + t]``."""
        poses = np.asarray(poses, dtype=np.float64)
        out = poses.copy()
        out[:, :3, :3] = self.rotation @ poses[:, :3, :3]
        out[:, :3, 3] = self.apply_points(poses[:, :3, 3])
        return out


def check_not_degenerate(points: np.ndarray, what: str = "positions") -> None:
    """Raise :class:`DegenerateGeometryError` if ``points`` (N, 3) are all identical or collinear.

    Uses the singular values ``s1 ≥ s2 ≥ s3`` of the centred covariance
    ``(1/n) Σ (p_i - μ)(p_i - μ)ᵀ``: identical when ``s1`` is at round-off
    level for the coordinates' magnitude, collinear when ``s2 / s1 < COLLINEAR_RTOL``.
    A planar set (``s3 = 0``) is fine: Umeyama determines R from two directions.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {p.shape}")
    centred = p - p.mean(axis=0)
    sv = np.linalg.svd(centred.T @ centred / p.shape[0], compute_uv=False)
    magnitude = 1.0 + float(np.max(np.abs(p))) if p.size else 1.0
    if sv[0] <= (IDENTICAL_RTOL * magnitude) ** 2:
        raise DegenerateGeometryError(f"degenerate geometry: all {p.shape[0]} matched {what} are identical")
    if sv[1] < COLLINEAR_RTOL * sv[0]:
        raise DegenerateGeometryError(
            f"degenerate geometry: the {p.shape[0]} matched {what} are collinear, so the alignment is undetermined"
        )


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> Sim3:
    """The Sim(3) (or SE(3) when ``with_scale`` is False) taking ``src`` (N, 3) onto ``dst`` (N, 3).

    Float64 throughout.  Raises :class:`DegenerateGeometryError` for identical or
    collinear point sets and ``ValueError`` for mismatched shapes.
    """
    x = np.asarray(src, dtype=np.float64)
    y = np.asarray(dst, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"src and dst must both be (N, 3), got {x.shape} and {y.shape}")
    check_not_degenerate(y, "ground-truth positions")
    check_not_degenerate(x, "estimated positions")
    n = x.shape[0]
    mu_x, mu_y = x.mean(axis=0), y.mean(axis=0)
    xc, yc = x - mu_x, y - mu_y
    var_x = float(np.sum(xc * xc)) / n
    cov = yc.T @ xc / n
    u, d, vt = np.linalg.svd(cov)
    s = np.ones(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:
        s[2] = -1.0
    rotation = (u * s) @ vt
    scale = float(np.sum(d * s) / var_x) if with_scale else 1.0
    translation = mu_y - scale * rotation @ mu_x
    return Sim3(rotation, translation, scale)


def align_positions(est: np.ndarray, gt: np.ndarray, mode: str = "sim3") -> Sim3:
    """The alignment of estimated onto ground-truth positions for ``mode`` in :data:`ALIGN_MODES`."""
    if mode == "sim3":
        return umeyama(est, gt, with_scale=True)
    if mode == "se3":
        return umeyama(est, gt, with_scale=False)
    if mode == "none":
        return Sim3.identity()
    raise ValueError(f"unknown alignment {mode!r}; use one of {', '.join(ALIGN_MODES)}")
