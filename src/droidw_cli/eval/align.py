"""Umeyama alignment of point sets (Sim(3), SE(3) or none), computed by evo.

``umeyama`` is :func:`evo.core.geometry.umeyama_alignment` (Umeyama 1991,
with the reflection fix) behind droidw's own guard: identical or collinear
point sets, for which the rotation is undetermined, raise
:class:`DegenerateGeometryError` with a message that says which, instead of
evo's generic rank error.  Aligned poses: ``T' = [R R_i | c R t_i + t]``.
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

    @staticmethod
    def from_matrix(m: np.ndarray) -> "Sim3":
        """From a 4×4 ``[[c R, t], [0, 1]]`` (evo's ``alignment_transformation_sim3``)."""
        m = np.asarray(m, dtype=np.float64)
        scale = float(np.cbrt(np.linalg.det(m[:3, :3])))
        return Sim3(m[:3, :3] / scale, m[:3, 3].copy(), scale)

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

    Uses the singular values ``s1 ≥ s2 ≥ s3`` of the centred covariance: identical when
    ``s1`` is at round-off level for the coordinates' magnitude, collinear when
    ``s2 / s1 < COLLINEAR_RTOL``.  A planar set (``s3 = 0``) is fine.
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


def check_alignable(est: np.ndarray, gt: np.ndarray) -> None:
    """Both matched position sets must determine a rotation (see :func:`check_not_degenerate`)."""
    check_not_degenerate(gt, "ground-truth positions")
    check_not_degenerate(est, "estimated positions")


def umeyama(src: np.ndarray, dst: np.ndarray, with_scale: bool = True) -> Sim3:
    """The Sim(3) (or SE(3) when ``with_scale`` is False) taking ``src`` (N, 3) onto ``dst`` (N, 3), by evo.

    Raises :class:`DegenerateGeometryError` for identical or collinear point sets
    and ``ValueError`` for mismatched shapes.
    """
    from evo.core.geometry import GeometryException, umeyama_alignment

    x = np.asarray(src, dtype=np.float64)
    y = np.asarray(dst, dtype=np.float64)
    if x.shape != y.shape or x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"src and dst must both be (N, 3), got {x.shape} and {y.shape}")
    check_alignable(x, y)
    try:
        rotation, translation, scale = umeyama_alignment(x.T, y.T, with_scale)
    except GeometryException as exc:
        raise DegenerateGeometryError(f"degenerate geometry: {exc}") from None
    return Sim3(np.asarray(rotation), np.asarray(translation), float(scale))


def align_positions(est: np.ndarray, gt: np.ndarray, mode: str = "sim3") -> Sim3:
    """The alignment of estimated onto ground-truth positions for ``mode`` in :data:`ALIGN_MODES`."""
    if mode == "sim3":
        return umeyama(est, gt, with_scale=True)
    if mode == "se3":
        return umeyama(est, gt, with_scale=False)
    if mode == "none":
        return Sim3.identity()
    raise ValueError(f"unknown alignment {mode!r}; use one of {', '.join(ALIGN_MODES)}")
