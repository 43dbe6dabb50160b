"""Seed refinement by region growing (the MobileSAM substitute) and inscribed-circle centres.

ADD-SLAM prompts MobileSAM with the centre of the largest inscribed circle
of the seed M_ic^d to obtain the whole object.  Without its weights, the
seed is grown instead over pixels that look alike and lie at a similar depth:

1. Seeds: 8-connected components of M_ic^d with at least ``min_seed_area``
   pixels, labelled 1…C.
2. Per component c: mean colour μ_c, RMS colour spread σ_c = sqrt(mean ‖I − μ_c‖²),
   median depth δ_c; colour tolerance t_c = max(color_tol, color_spread · σ_c)
   (textured objects get a tolerance matching their own texture).
3. Growth, repeated at most ``grow_steps`` times or until nothing changes
   (and, with ``max_growth`` > 0, stopped per component once it has
   ``max_growth`` times its seed's area):
   every unlabelled pixel p takes the largest label L among its 4-neighbours q
   with |D_p − D_q| ≤ depth_step_tol · D_p (no label crosses a depth edge) when
       ‖I_p − μ_L‖ ≤ t_L   and   |D_p − δ_L| ≤ depth_rel_tol · δ_L   (D_p > 0),
   i.e. a morphological dilation masked by the per-component similarity test,
   done with tensor shifts (no pixel loops).  The statistics stay those of
   the seed, so the region cannot drift along a gradient.  With the grid's
   focal lengths, a pixel is added only where the surface faces the camera
   within ``max_slant`` (:func:`surface_slant`): the floor at a walker's feet
   continues the walker's depth and colour, but is seen at a grazing angle.
4. Components smaller than ``min_object_area`` after growing are dropped.

Centre of an object: the maximum of the Euclidean distance transform
(``cv2.distanceTransform``) of its mask, with the image border counting as
background (the mask is padded by one background pixel), ties broken by the
first pixel in row-major order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import Tensor

from droidw_cli.dynamics.params import DetectionParams


@dataclass(frozen=True)
class Objects:
    """Labelled objects of one frame.

    Attributes:
        labels: (h, w) long, 0 background, 1…C objects.
        centres: (C, 2) float (x, y) inscribed-circle centres (grid pixels).
        radii: (C,) float inscribed-circle radii (pixels).
        areas: (C,) long pixel counts.
    """

    labels: Tensor
    centres: Tensor
    radii: Tensor
    areas: Tensor

    @property
    def mask(self) -> Tensor:
        return self.labels > 0

    @property
    def count(self) -> int:
        return int(self.areas.numel())


def label_components(mask, min_area: int = 1) -> Tensor:
    """8-connected components of a (h, w) bool mask as labels 1…C (row-major order of first pixel).

    Components with fewer than ``min_area`` pixels are removed.  Returns a long tensor (h, w).
    """
    m = mask.detach().cpu().numpy() if isinstance(mask, Tensor) else np.asarray(mask)
    if m.ndim != 2:
        raise ValueError(f"mask must be (h, w), got shape {m.shape}")
    n, lab, stats, _ = cv2.connectedComponentsWithStats(m.astype(np.uint8), connectivity=8)
    keep = np.zeros(n, dtype=np.int64)
    big = [i for i in range(1, n) if stats[i, cv2.CC_STAT_AREA] >= min_area]
    keep[big] = np.arange(1, len(big) + 1)
    out = torch.from_numpy(keep[lab])
    return out.to(mask.device) if isinstance(mask, Tensor) else out


def _relabel(labels: Tensor, min_area: int) -> Tensor:
    """Drop labels with fewer than ``min_area`` pixels and renumber the rest 1…C in order."""
    count = int(labels.max()) if labels.numel() else 0
    areas = torch.bincount(labels.reshape(-1), minlength=count + 1)
    keep = areas >= min_area
    keep[0] = False
    new = torch.zeros(count + 1, dtype=torch.long, device=labels.device)
    new[keep] = torch.arange(1, int(keep.sum()) + 1, device=labels.device)
    return new[labels]


def _neighbours(x: Tensor) -> Tensor:
    """(4, h, w): each pixel's neighbour above, below, left and right (0 beyond the border)."""
    padded = torch.nn.functional.pad(x, (1, 1, 1, 1))
    return torch.stack((padded[:-2, 1:-1], padded[2:, 1:-1], padded[1:-1, :-2], padded[1:-1, 2:]))


def surface_slant(depth: Tensor, focal: tuple[float, float]) -> Tensor:
    """tan θ per pixel (h, w), θ the angle between the surface normal and the optical axis; inf where unknown.

    For a plane n·X = c the depth along the ray K⁻¹p̃ is D = c / (n·K⁻¹p̃), so
    f_x ∂D/∂u / D = −n_x / (n·K⁻¹p̃) and likewise in v:

        tan θ = sqrt((f_x ∂D/∂u)² + (f_y ∂D/∂v)²) / D

    (exact at the principal point).  Each derivative is the smaller of the
    forward and backward differences, so a pixel beside a depth edge keeps the
    slope of its own side.  A fronto-parallel walker reads about 0, the floor a
    few metres ahead of a camera at head height about tan 60°.
    """
    near = _neighbours(depth)  # above, below, left, right; 0 where unknown or beyond the border
    step = torch.where(near > 0, (near - depth).abs(), torch.full_like(near, float("inf")))
    dv, du = step[:2].amin(0), step[2:].amin(0)
    slant = torch.sqrt((focal[0] * du) ** 2 + (focal[1] * dv) ** 2) / depth.clamp(min=1e-6)
    return torch.where(depth > 0, slant, torch.full_like(slant, float("inf")))


def grow_regions(labels: Tensor, image: Tensor, depth: Tensor, params: DetectionParams | None = None,
                 allowed: Tensor | None = None, focal: tuple[float, float] | None = None) -> Tensor:
    """Grow labelled seeds (h, w) over similar pixels (see the module docstring, steps 2-3).

    ``image`` (h, w, 3) colour in [0, 1], ``depth`` (h, w) metres (≤ 0 unknown); ``allowed``
    (h, w) bool, optional, further restricts the pixels that may be added; ``focal`` (f_x, f_y) of
    the grid in pixels turns on the slant limit (``params.max_slant``).
    """
    params = params or DetectionParams()
    h, w = labels.shape
    if image.shape != (h, w, 3) or depth.shape != (h, w):
        raise ValueError("labels (h, w), image (h, w, 3) and depth (h, w) must match")
    count = int(labels.max()) if labels.numel() else 0
    if count == 0 or params.grow_steps == 0:
        return labels.clone()
    if focal is not None and params.max_slant < 90:
        facing = surface_slant(depth, focal) <= math.tan(math.radians(params.max_slant))
        allowed = facing if allowed is None else allowed & facing
    image = image.to(depth.dtype)
    flat = labels.reshape(-1)
    seed = flat > 0
    n_pix = torch.bincount(flat, minlength=count + 1).to(depth.dtype).clamp(min=1).unsqueeze(1)
    mu = torch.zeros(count + 1, 3, dtype=depth.dtype, device=depth.device)
    mu.index_add_(0, flat[seed], image.reshape(-1, 3)[seed])
    mu = mu / n_pix
    sq = ((image.reshape(-1, 3) - mu[flat]) ** 2).sum(-1)
    spread = torch.zeros(count + 1, dtype=depth.dtype, device=depth.device).index_add_(0, flat[seed], sq[seed])
    tol_c = torch.clamp(params.color_spread * (spread / n_pix[:, 0]).sqrt(), min=params.color_tol)
    delta = torch.ones(count + 1, dtype=depth.dtype, device=depth.device)
    dflat = depth.reshape(-1)
    for c in range(1, count + 1):  # a handful of components
        dc = dflat[(flat == c) & (dflat > 0)]
        if dc.numel():
            delta[c] = dc.median()
    tol_d = params.depth_rel_tol * delta

    lab = labels.clone()
    cap = params.max_growth * n_pix[:, 0] if params.max_growth > 0 else None
    # a neighbour passes its label on only across a depth step of at most depth_step_tol of the pixel's depth
    continuous = None
    if params.depth_step_tol > 0:
        near = _neighbours(depth)
        continuous = (near - depth).abs() <= params.depth_step_tol * depth
    for _ in range(params.grow_steps):
        near = _neighbours(lab)
        if continuous is not None:
            near = torch.where(continuous, near, torch.zeros_like(near))
        cand = near.amax(0)
        if cap is not None:
            full = torch.bincount(lab.reshape(-1), minlength=count + 1).to(cap.dtype) >= cap
            full[0] = True
            cand = torch.where(full[cand], torch.zeros_like(cand), cand)
        col_ok = (image - mu[cand]).norm(dim=-1) <= tol_c[cand]
        dep_ok = (depth > 0) & ((depth - delta[cand]).abs() <= tol_d[cand])
        add = (lab == 0) & (cand > 0) & col_ok & dep_ok
        if allowed is not None:
            add &= allowed
        if not bool(add.any()):
            break
        lab = torch.where(add, cand, lab)
    return lab


def inscribed_centres(labels: Tensor) -> tuple[Tensor, Tensor]:
    """Inscribed-circle centres (C, 2) as (x, y) and radii (C,) of labels 1…C (h, w)."""
    lab = labels.detach().cpu().numpy()
    count = int(lab.max()) if lab.size else 0
    centres = np.zeros((count, 2), dtype=np.float64)
    radii = np.zeros(count, dtype=np.float64)
    for c in range(1, count + 1):  # per component, on its bounding box
        ys, xs = np.nonzero(lab == c)
        if ys.size == 0:
            continue
        y0, x0 = ys.min(), xs.min()
        sub = np.zeros((ys.max() - y0 + 3, xs.max() - x0 + 3), dtype=np.uint8)
        sub[ys - y0 + 1, xs - x0 + 1] = 1
        dist = cv2.distanceTransform(sub, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        iy, ix = np.unravel_index(int(np.argmax(dist)), dist.shape)
        centres[c - 1] = (ix - 1 + x0, iy - 1 + y0)
        radii[c - 1] = dist[iy, ix]
    return (torch.from_numpy(centres).to(labels.device), torch.from_numpy(radii).to(labels.device))


def object_centre(mask) -> tuple[float, float]:
    """ADD-SLAM's object centre: the inscribed-circle centre (x, y) of the mask's largest part (by radius)."""
    centres, radii = inscribed_centres(label_components(mask))
    x, y = centres[int(torch.argmax(radii))].tolist()
    return float(x), float(y)


def make_objects(labels: Tensor, min_area: int = 1) -> Objects:
    """Objects (labels, centres, radii, areas) of a label map, dropping labels under ``min_area``."""
    labels = _relabel(labels.long(), min_area)
    count = int(labels.max()) if labels.numel() else 0
    areas = torch.bincount(labels.reshape(-1), minlength=count + 1)[1:]
    centres, radii = inscribed_centres(labels)
    return Objects(labels, centres, radii, areas)


def refine_mask(seed: Tensor, image: Tensor, depth: Tensor, params: DetectionParams | None = None,
                allowed: Tensor | None = None, focal: tuple[float, float] | None = None) -> Objects:
    """Seed mask (h, w) → grown, labelled objects with their centres (steps 1-4)."""
    params = params or DetectionParams()
    labels = label_components(seed, params.min_seed_area)
    grown = grow_regions(labels, image, depth, params, allowed, focal)
    return make_objects(grown, params.min_object_area)
