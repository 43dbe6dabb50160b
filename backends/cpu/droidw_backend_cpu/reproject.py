"""Eq. 1 with few passes over memory: the rigid reprojection the CPU hot paths share.

Same maths as :func:`droidw_cli.geometry.projection.project_edges` (see there):

    (X, Y, Z) = R_ij (x̄, ȳ, 1) + t_ij d,     z = 1/Z,   (x̂, ŷ) = (X z, Y z),
    p_ij = (fx x̂ + cx, fy ŷ + cy),     valid = d > 0 ∧ 1/d ≥ m ∧ Z/d ≥ m

but laid out for the CPU: (x̂, ŷ) and p_ij are (E, 2, HW) (one op for both
components), the disparity-only half of ``valid`` is computed once per frame,
and the rays (x̄, ȳ, 1) once per call.  :func:`bilinear_rows` gives the four
bilinear corners of a point as one row (for ``embedding_bag`` and gradient
scatters); :func:`sample_scalar` samples scalar maps in one ``grid_sample`` pass.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as tnf
from torch import Tensor

from droidw_cli.geometry.projection import pixel_grid, relative_poses


@dataclass(frozen=True)
class Projected:
    """The reprojection of the pixels of frames ii into frames jj (E edges).

    Attributes:
        xy: (E, 2, HW) x̂, ŷ.
        coords: (E, 2, HW) p_ij as (x, y).
        z: (E, HW) 1/Z (1 where invalid).
        disp: (E, HW) d of frame ii.
        valid: (E, HW) bool.
    """

    xy: Tensor
    coords: Tensor
    z: Tensor
    disp: Tensor
    valid: Tensor


class FrameGeometry:
    """Per-call constants of one window: rays, intrinsics, per-frame disparity tests.

    Args:
        poses (N, 7), disps (N, H, W), intrinsics (4,) as in :class:`droidw_cli.ba.types.BAState`.
    """

    def __init__(self, poses: Tensor, disps: Tensor, intrinsics: Tensor, min_depth: float) -> None:
        n, h, w = disps.shape
        dev, dt = disps.device, disps.dtype
        self.poses = poses
        self.fx, self.fy, self.cx, self.cy = (float(v) for v in intrinsics.tolist())
        gx, gy = pixel_grid(h, w, dev, dt)
        self.xbar, self.ybar = (gx - self.cx) / self.fx, (gy - self.cy) / self.fy
        self.ray = torch.stack((self.xbar, self.ybar, torch.ones_like(self.xbar)))  # (3, HW)
        self.focal = torch.tensor([self.fx, self.fy], dtype=dt, device=dev).view(1, 2, 1)
        self.centre = torch.tensor([self.cx, self.cy], dtype=dt, device=dev).view(1, 2, 1)
        self.dflat = disps.reshape(n, h * w)
        self.disp_ok = (self.dflat > 0) & (self.dflat * min_depth <= 1.0)
        self.disp_min = self.dflat * min_depth

    def relative(self, ii: Tensor, jj: Tensor) -> tuple[Tensor, Tensor]:
        """(R_ij (E, 3, 3), t_ij (E, 3))."""
        return relative_poses(self.poses, ii, jj)

    def project(self, ii: Tensor, rot: Tensor, trans: Tensor) -> Projected:
        """Project the pixels of frames ii with the relative poses (rot, trans) of their edges."""
        d = self.dflat.index_select(0, ii)
        pts = torch.matmul(rot, self.ray).addcmul_(trans.unsqueeze(2), d.unsqueeze(1))  # (E, 3, HW)
        big_z = pts[:, 2]
        valid = self.disp_ok.index_select(0, ii).logical_and_(big_z >= self.disp_min.index_select(0, ii))
        z = torch.where(valid, big_z, 1.0).reciprocal_()
        xy = pts[:, :2].mul_(z.unsqueeze(1))
        coords = torch.addcmul(self.centre, xy, self.focal)
        return Projected(xy, coords, z, d, valid)


def bilinear_rows(x: Tensor, y: Tensor, h: int, w: int) -> tuple[Tensor, Tensor]:
    """Corner indices (..., 4) long and weights (..., 4) of the points (x, y) (...).

    The same corners, weights and order as
    :func:`droidw_cli.geometry.sampling.bilinear_corners` (border clamp,
    x0 = min(⌊x⌋, W − 2)), written as one row of four per point, index
    y0·W + x0 + (0, 1, W, W + 1), without stacking four separate maps.
    """
    if h < 2 or w < 2:
        raise ValueError(f"bilinear sampling needs a grid of at least 2 × 2, got {h} × {w}")
    xc, yc = x.clamp(0.0, float(w - 1)), y.clamp(0.0, float(h - 1))
    x0, y0 = xc.floor().clamp_(max=w - 2), yc.floor().clamp_(max=h - 2)
    ax, ay = xc.sub_(x0), yc.sub_(y0)
    bx, by = 1.0 - ax, 1.0 - ay
    idx = y0.mul_(w).add_(x0).long().unsqueeze(-1) + torch.tensor([0, 1, w, w + 1], device=x.device)
    wts = torch.empty(idx.shape, dtype=x.dtype, device=x.device)
    torch.mul(bx, by, out=wts[..., 0])
    torch.mul(ax, by, out=wts[..., 1])
    torch.mul(bx, ay, out=wts[..., 2])
    torch.mul(ax, ay, out=wts[..., 3])
    return idx, wts


def sample_scalar(maps: Tensor, frames: Tensor, x: Tensor, y: Tensor) -> Tensor:
    """Bilinear samples (E, P) of scalar maps (N, H, W) at (x, y) (E, P) in frames ``frames`` (E,).

    The values of :func:`droidw_cli.geometry.sampling.sample_maps` (border clamp,
    corners at integer pixels), computed by ``grid_sample`` (align_corners, border
    padding) in one pass: x is normalised to 2x/(W − 1) − 1 and back inside, which
    moves it by float round-off only (≈ 1e-7·W px).
    """
    n, h, w = maps.shape
    e, p = x.shape
    grid = torch.empty(e, 1, p, 2, dtype=maps.dtype, device=maps.device)
    torch.mul(x, 2.0 / (w - 1), out=grid[:, 0, :, 0]).sub_(1.0)
    torch.mul(y, 2.0 / (h - 1), out=grid[:, 0, :, 1]).sub_(1.0)
    src = maps.index_select(0, frames).unsqueeze(1)  # (E, 1, H, W)
    out = tnf.grid_sample(src, grid, mode="bilinear", padding_mode="border", align_corners=True)
    return out.view(e, p)


#: largest projection kept by a :class:`ProjectionCache` (bytes of xy, coords, z and valid)
DEFAULT_CACHE_BYTES = 64 * 2**20


def version(t: Tensor) -> int | None:
    """t's version counter (bumped by every in-place write), or None where torch keeps none
    (tensors made in inference mode): such tensors are never reused."""
    try:
        return t._version
    except RuntimeError:
        return None


def _stamp(t: Tensor) -> tuple:
    """What identifies a tensor's current contents cheaply: the object, its version counter."""
    return (id(t), version(t))


def _stamps(*tensors: Tensor) -> tuple | None:
    """The stamps of tensors, or None when one of them has no version counter."""
    out = tuple(_stamp(t) for t in tensors)
    return None if any(v is None for _, v in out) else out


class ProjectionCache:
    """The last reprojection of an edge set, reused while the state it came from is unchanged.

    One BA iteration of the tracker projects the same edges up to three times
    (evidence maps, uncertainty step, GN step) with the same poses and
    disparities.  The projection of an edge depends only on its pair (i, j) and
    the state, so a stored projection serves any edge list whose pairs it
    contains (rows are looked up per pair; the same list in the same order is
    used as is).  Validity is checked on the tensors themselves: the stored
    poses, disparities and intrinsics must be the very objects passed, with
    unchanged version counters (every in-place write bumps them), and the
    stored results must be unmodified too (they may have been handed out as views).
    """

    def __init__(self, max_bytes: int = DEFAULT_CACHE_BYTES) -> None:
        self.max_bytes = int(max_bytes)
        self._entry: dict | None = None

    def clear(self) -> None:
        self._entry = None

    def _valid_for(self, poses: Tensor, disps: Tensor, intrinsics: Tensor, min_depth: float) -> dict | None:
        e = self._entry
        if e is None or e["min_depth"] != min_depth:
            return None
        if e["held"][0] is not poses or e["held"][1] is not disps or e["held"][2] is not intrinsics:
            return None
        if e["inputs"] != _stamps(poses, disps, intrinsics) or e["outputs"] != _stamps(*e["proj"]):
            return None
        return e

    def peek(self, poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
             min_depth: float) -> tuple[Projected, Tensor, Tensor] | None:
        """(projection, R_ij, t_ij) of the edges (ii, jj) when the cache has them, else None."""
        e = self._valid_for(poses, disps, intrinsics, min_depth)
        if e is None:
            return None
        if e["ii"] is ii and e["jj"] is jj and e["edges"] == _stamps(ii, jj):
            return self._rows(e, None, ii)
        if ii.numel() and (int(ii.max()) >= e["n"] or int(jj.max()) >= e["n"]):
            return None
        rows = e["lookup"][ii * e["n"] + jj]
        if bool((rows < 0).any()):
            return None
        return self._rows(e, rows, ii)

    def get(self, poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
            min_depth: float) -> tuple[Projected, Tensor, Tensor]:
        """(projection, R_ij, t_ij) of the edges (ii, jj): from the cache when possible, else computed (and kept)."""
        hit = self.peek(poses, disps, intrinsics, ii, jj, min_depth)
        if hit is not None:
            return hit
        geo = FrameGeometry(poses, disps, intrinsics, min_depth)
        rot, trans = geo.relative(ii, jj)
        proj = geo.project(ii, rot, trans)
        hw = disps.shape[1] * disps.shape[2]
        small = ii.shape[0] * hw * (5 * proj.xy.element_size() + 1) <= self.max_bytes
        if small and _stamps(poses, disps, intrinsics, ii, jj) is not None:
            self._store(poses, disps, intrinsics, ii, jj, min_depth, proj, rot, trans)
        return proj, rot, trans

    def _store(self, poses, disps, intrinsics, ii, jj, min_depth, proj: Projected, rot, trans) -> None:
        n = disps.shape[0]
        lookup = torch.full((n * n,), -1, dtype=torch.long, device=ii.device)
        lookup[ii * n + jj] = torch.arange(ii.shape[0], device=ii.device)
        kept = (proj.xy, proj.coords, proj.z, proj.valid)
        self._entry = {
            "held": (poses, disps, intrinsics), "inputs": _stamps(poses, disps, intrinsics),
            "min_depth": min_depth, "ii": ii, "jj": jj, "edges": _stamps(ii, jj), "n": n,
            "lookup": lookup, "proj": kept, "outputs": _stamps(*kept),
            "rot": rot, "trans": trans, "dflat": disps.reshape(n, -1),
        }

    @staticmethod
    def _rows(e: dict, rows: Tensor | None, ii: Tensor) -> tuple[Projected, Tensor, Tensor]:
        xy, coords, z, valid = e["proj"]
        rot, trans = e["rot"], e["trans"]
        if rows is not None:
            xy, coords, z, valid = (t.index_select(0, rows) for t in (xy, coords, z, valid))
            rot, trans = rot.index_select(0, rows), trans.index_select(0, rows)
        return Projected(xy, coords, z, e["dflat"].index_select(0, ii), valid), rot, trans
