"""The Gaussians of a 3DGS map and the activations that turn their parameters into geometry and colour.

Each Gaussian i (Kerbl et al. 2023, "3D Gaussian Splatting", Sec. 4) has

* a mean μᵢ ∈ ℝ³ (world frame),
* a covariance Σᵢ = Rᵢ Sᵢ Sᵢᵀ Rᵢᵀ (3DGS Eq. 6), stored as log-scales sᵢ (Sᵢ = diag(exp sᵢ)) and a
  quaternion qᵢ = (w, x, y, z) (normalised before use, Rᵢ = R(qᵢ / ‖qᵢ‖)),
* an opacity oᵢ = σ(ℓᵢ) stored as the logit ℓᵢ,
* a colour from the spherical-harmonics coefficient of degree 0: cᵢ = max(0, ½ + C₀ fᵢ), C₀ = 1 / (2√π)
  (the constant SH band), so that the PLY's ``f_dc`` fields are fᵢ as every 3DGS viewer reads them.

Dynamic (temporal) Gaussians (ADD-SLAM Eq. 15) also carry a time ``t`` and an ``object_id``.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

SH_C0 = 0.28209479177387814  # 1 / (2 √π)


def rgb_to_dc(rgb: torch.Tensor) -> torch.Tensor:
    """The degree-0 SH coefficient whose colour is ``rgb`` (in [0, 1])."""
    return (rgb - 0.5) / SH_C0


def dc_to_rgb(dc: torch.Tensor) -> torch.Tensor:
    """c = max(0, ½ + C₀ f) (the 3DGS colour of SH degree 0 seen from any direction)."""
    return torch.clamp_min(0.5 + SH_C0 * dc, 0.0)


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """(N, 4) quaternions w, x, y, z (any norm) → (N, 3, 3) rotation matrices."""
    q = q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(*q.shape[:-1], 3, 3)


def logit(p: torch.Tensor | float) -> torch.Tensor:
    p = torch.as_tensor(p, dtype=torch.float32).clamp(1e-6, 1 - 1e-6)
    return torch.log(p / (1 - p))


@dataclass
class Gaussians:
    """N Gaussians as tensors: ``means`` (N, 3), ``log_scales`` (N, 3), ``quats`` (N, 4) w-x-y-z,
    ``opacity_logits`` (N,), ``dc`` (N, 3); dynamic ones also ``t`` (N,) float64 and ``object_id`` (N,) int."""

    means: torch.Tensor
    log_scales: torch.Tensor
    quats: torch.Tensor
    opacity_logits: torch.Tensor
    dc: torch.Tensor
    t: torch.Tensor | None = None
    object_id: torch.Tensor | None = None

    TRAINABLE = ("means", "log_scales", "quats", "opacity_logits", "dc")

    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def opacity(self) -> torch.Tensor:
        return torch.sigmoid(self.opacity_logits)

    @property
    def rgb(self) -> torch.Tensor:
        return dc_to_rgb(self.dc)

    def covariances(self) -> torch.Tensor:
        """Σ = R S Sᵀ Rᵀ (3DGS Eq. 6), (N, 3, 3)."""
        m = quat_to_rotmat(self.quats) * torch.exp(self.log_scales)[:, None, :]
        return m @ m.transpose(1, 2)

    @staticmethod
    def empty(dtype=torch.float32) -> "Gaussians":
        z = torch.zeros
        return Gaussians(z(0, 3, dtype=dtype), z(0, 3, dtype=dtype), z(0, 4, dtype=dtype), z(0, dtype=dtype),
                         z(0, 3, dtype=dtype))

    @staticmethod
    def isotropic(means: torch.Tensor, rgb: torch.Tensor, sigma: torch.Tensor, opacity: float) -> "Gaussians":
        """Round Gaussians of standard deviation ``sigma`` (N,), colour ``rgb`` (N, 3) and one opacity."""
        n = means.shape[0]
        quats = torch.zeros(n, 4, dtype=means.dtype)
        quats[:, 0] = 1
        return Gaussians(means.clone(), torch.log(sigma.clamp_min(1e-8))[:, None].repeat(1, 3).to(means.dtype),
                         quats, torch.full((n,), float(logit(opacity)), dtype=means.dtype), rgb_to_dc(rgb).to(means.dtype))

    def select(self, keep: torch.Tensor) -> "Gaussians":
        """The Gaussians where ``keep`` (bool mask or indices) selects, detached."""
        pick = (lambda v: None if v is None else v.detach()[keep].clone())
        return Gaussians(*(pick(getattr(self, n)) for n in self.TRAINABLE), t=pick(self.t),
                         object_id=pick(self.object_id))

    def detached(self) -> "Gaussians":
        return self.select(torch.arange(len(self)))

    @staticmethod
    def cat(parts: list["Gaussians"]) -> "Gaussians":
        """All Gaussians of ``parts`` in order (time and object id kept only when every part has them)."""
        parts = [p for p in parts if p is not None]
        if not parts:
            return Gaussians.empty()
        fields = [torch.cat([getattr(p, n) for p in parts]) for n in Gaussians.TRAINABLE]
        t = torch.cat([p.t for p in parts]) if all(p.t is not None for p in parts) else None
        oid = torch.cat([p.object_id for p in parts]) if all(p.object_id is not None for p in parts) else None
        return Gaussians(*fields, t=t, object_id=oid)
