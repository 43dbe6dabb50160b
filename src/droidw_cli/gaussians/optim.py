"""Adam over the Gaussians' parameter tensors, whose rows can grow (densification) and shrink (pruning).

Adam (Kingma & Ba 2015): m ← β₁ m + (1 − β₁) g, v ← β₂ v + (1 − β₂) g², θ ← θ − η m̂ / (√v̂ + ε) with the
bias-corrected m̂, v̂.  The moments live beside each tensor's rows, so new Gaussians start with zero moments
and pruned ones take theirs with them; the step counter is per row (a row added late gets its own bias
correction).
"""

from __future__ import annotations

import torch

from droidw_cli.gaussians.model import Gaussians


class GaussianAdam:
    """Adam on the trainable fields of a :class:`Gaussians` (``lrs``: field → learning rate)."""

    def __init__(self, g: Gaussians, lrs: dict[str, float], betas=(0.9, 0.999), eps: float = 1e-15) -> None:
        self.g, self.lrs, self.betas, self.eps = g, dict(lrs), betas, eps
        self.m = {n: torch.zeros_like(getattr(g, n)) for n in lrs}
        self.v = {n: torch.zeros_like(getattr(g, n)) for n in lrs}
        self.count = torch.zeros(len(g))
        for n in lrs:
            getattr(g, n).requires_grad_(True)

    @torch.no_grad()
    def step(self) -> None:
        b1, b2 = self.betas
        self.count += 1
        for n, lr in self.lrs.items():
            p = getattr(self.g, n)
            if p.grad is None:
                continue
            grad = p.grad
            seen = (grad != 0).reshape(len(grad), -1).any(1)  # rows the render saw: only they move
            self.m[n].mul_(b1).add_((1 - b1) * grad)
            self.v[n].mul_(b2).addcmul_(grad, grad, value=1 - b2)
            shape = (-1,) + (1,) * (p.dim() - 1)
            c1 = (1 - b1 ** self.count).view(shape)
            c2 = (1 - b2 ** self.count).view(shape)
            upd = lr * (self.m[n] / c1) / ((self.v[n] / c2).sqrt() + self.eps)
            p.sub_(upd * seen.view(shape).to(p.dtype))
            p.grad = None

    def zero_grad(self) -> None:
        for n in self.lrs:
            getattr(self.g, n).grad = None

    def append(self, new: Gaussians) -> None:
        """Add ``new``'s rows (zero moments)."""
        for n in Gaussians.TRAINABLE:
            old = getattr(self.g, n).detach()
            setattr(self.g, n, torch.cat([old, getattr(new, n).detach().to(old.dtype)]))
        for extra in ("t", "object_id"):
            a, b = getattr(self.g, extra), getattr(new, extra)
            if a is not None and b is not None:
                setattr(self.g, extra, torch.cat([a, b]))
        for n in self.lrs:
            self.m[n] = torch.cat([self.m[n], torch.zeros_like(getattr(new, n))])
            self.v[n] = torch.cat([self.v[n], torch.zeros_like(getattr(new, n))])
            getattr(self.g, n).requires_grad_(True)
        self.count = torch.cat([self.count, torch.zeros(len(new))])

    def keep(self, mask: torch.Tensor) -> None:
        """Keep only the rows where ``mask`` is True."""
        for n in Gaussians.TRAINABLE:
            setattr(self.g, n, getattr(self.g, n).detach()[mask].clone())
        for extra in ("t", "object_id"):
            if getattr(self.g, extra) is not None:
                setattr(self.g, extra, getattr(self.g, extra)[mask])
        for n in self.lrs:
            self.m[n], self.v[n] = self.m[n][mask], self.v[n][mask]
            getattr(self.g, n).requires_grad_(True)
        self.count = self.count[mask]
