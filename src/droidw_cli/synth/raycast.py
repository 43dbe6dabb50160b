"""Analytic ray casting against oriented boxes, vectorised over pixels.

Pixel (u, v) casts the ray X(t) = o + t·R d,  d = ((u − cx)/fx, (v − cy)/fy, 1),
from the camera centre o with camera-to-world rotation R.  Because d_z = 1,
the ray parameter t of a hit *is* the z-depth.

A box has centre c, rotation B (box-to-world) and half extents h.  In box
coordinates the ray is o' = Bᵀ(o − c), d' = BᵀR d, and the slab method gives

    t_near = maxₖ min(t⁻ₖ, t⁺ₖ),   t_far = minₖ max(t⁻ₖ, t⁺ₖ),   t^±ₖ = (±hₖ − o'ₖ)/d'ₖ,

a hit when t_near ≤ t_far and t_near > 0, entering through the face of the
axis k attaining the max (the −hₖ face when d'ₖ > 0).  The room is a box seen
from inside: the ray leaves it at t = minₖ (sign(d'ₖ)hₖ − o'ₖ)/d'ₖ.  The
visible surface is the hit of least t over all boxes.

Each face f = 2k + s (s = 1 for the +hₖ face) has a texture rectangle in an
atlas, (ox, oy, w − 1, h − 1) texels; the hit point's face coordinates
(u_f, v_f) in metres from the face corner map to atlas pixel
(ox + clip(ρ u_f − ½), oy + clip(ρ v_f − ½)), and one ``cv2.remap`` gathers
the colours of the whole image.  Face axes: k = 0 → (y, z), k = 1 → (x, z),
k = 2 → (x, y); v is "up" on vertical faces.

For speed a box is only tested inside the bounding rectangle of its
projected corners (the full image when a corner is behind the camera).

A box may carry its own texel density (``Box.rho``; a street's far facades
need fewer texels than its near kerb).  The room seen from inside may have an
open top (``Box.sky``, a street): a ray that leaves it upwards sees the sky,
which is at infinity.  It keeps depth ∞ (so every other surface is nearer)
and takes its colour from the sky panel by direction alone: with the ray's
world direction r, azimuth α = atan2(r_x, r_y) and elevation
ε = atan2(r_z, ‖(r_x, r_y)‖), the panel's texel is
(ox + (α/2π + ½)(w − 1), oy + (2ε/π)(h − 1)), the same for every camera
position, as a sky at infinity is.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

EPS = 1e-6
_U_AXIS = (1, 0, 0)
_V_AXIS = (2, 2, 1)
_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64)


@dataclass(frozen=True, eq=False)
class Box:
    """An oriented box in the world: centre (3,), rotation (3, 3) box-to-world, half extents (3,).

    ``faces`` (6, 4) float32: the atlas rectangle (ox, oy, w − 1, h − 1) of face 2k + s.
    ``dynamic``: pixels where it is nearest belong to the mask.  ``inside``: the room (seen from within).
    """

    centre: np.ndarray
    rotation: np.ndarray
    half: np.ndarray
    faces: np.ndarray
    dynamic: bool = False
    inside: bool = False
    rho: float | None = None  # texels per metre (None: the caster's)
    sky: np.ndarray | None = None  # (4,) atlas rect of the sky panel: the inside box's top face is open sky


@dataclass
class Hits:
    """Per-pixel result of a cast: depth (inf = nothing), atlas coordinates, dynamic flag."""

    depth: np.ndarray
    map_x: np.ndarray
    map_y: np.ndarray
    dynamic: np.ndarray


class RayCaster:
    """Casts the rays of a fixed pinhole camera (intrinsics fx, fy, cx, cy; size W × H)."""

    def __init__(self, intrinsics, width: int, height: int, rho: float):
        fx, fy, cx, cy = (float(v) for v in intrinsics)
        self.fx, self.fy, self.cx, self.cy = fx, fy, cx, cy
        self.width, self.height, self.rho = int(width), int(height), np.float32(rho)
        self.xs = ((np.arange(width) - cx) / fx).astype(np.float32)
        self.ys = ((np.arange(height) - cy) / fy).astype(np.float32)

    def cast(self, boxes: list[Box], pose_c2w: np.ndarray) -> Hits:
        h, w = self.height, self.width
        hits = Hits(np.full((h, w), np.inf, np.float32), np.zeros((h, w), np.float32),
                    np.zeros((h, w), np.float32), np.zeros((h, w), bool))
        rc, oc = np.asarray(pose_c2w[:3, :3], np.float64), np.asarray(pose_c2w[:3, 3], np.float64)
        for box in boxes:
            rect = (0, h, 0, w) if box.inside else self._rect(box, rc, oc)
            if rect is not None:
                self._cast_box(box, rc, oc, rect, hits)
        return hits

    def _rect(self, box: Box, rc: np.ndarray, oc: np.ndarray) -> tuple[int, int, int, int] | None:
        """Pixel rows/cols (v0, v1, u0, u1) that can see ``box``; None when it is entirely behind the camera."""
        corners = box.centre + (_SIGNS * box.half) @ box.rotation.T
        cam = (corners - oc) @ rc
        z = cam[:, 2]
        if np.all(z <= EPS):
            return None
        if np.any(z <= 1e-3):
            return 0, self.height, 0, self.width
        u = self.fx * cam[:, 0] / z + self.cx
        v = self.fy * cam[:, 1] / z + self.cy
        u0, u1 = max(0, int(np.floor(u.min()))), min(self.width, int(np.ceil(u.max())) + 1)
        v0, v1 = max(0, int(np.floor(v.min()))), min(self.height, int(np.ceil(v.max())) + 1)
        if u0 >= u1 or v0 >= v1:
            return None
        return v0, v1, u0, u1

    def _cast_box(self, box: Box, rc: np.ndarray, oc: np.ndarray, rect, hits: Hits) -> None:
        v0, v1, u0, u1 = rect
        m = (box.rotation.T @ rc).astype(np.float32)  # camera ray → box frame
        o = (box.rotation.T @ (oc - box.centre)).astype(np.float32)
        half = box.half.astype(np.float32)
        xs, ys = self.xs[None, u0:u1], self.ys[v0:v1, None]
        d = [m[c, 0] * xs + (m[c, 1] * ys + m[c, 2]) for c in range(3)]
        with np.errstate(divide="ignore", invalid="ignore"):
            if box.inside:
                plus = [d[c] > 0 for c in range(3)]
                tk = [np.where(plus[c], half[c] - o[c], -half[c] - o[c]) / d[c] for c in range(3)]
                t = np.minimum(np.minimum(tk[0], tk[1]), tk[2])
                ok = np.isfinite(t)
            else:
                tn, tf = [], []
                for c in range(3):
                    inv = np.float32(1.0) / d[c]
                    ta, tb = (-half[c] - o[c]) * inv, (half[c] - o[c]) * inv
                    tn.append(np.minimum(ta, tb))
                    tf.append(np.maximum(ta, tb))
                tk = tn
                t = np.maximum(np.maximum(tn[0], tn[1]), tn[2])
                ok = (t <= np.minimum(np.minimum(tf[0], tf[1]), tf[2])) & (t > EPS)
                plus = [d[c] < 0 for c in range(3)]
        depth = hits.depth[v0:v1, u0:u1]
        win = ok & (t < depth)
        if not win.any():
            return
        k0 = tk[0] == t
        k2 = ~k0 & (tk[2] == t)
        # hit point in box coordinates, measured from the box's low corner (garbage where not hit)
        with np.errstate(invalid="ignore"):
            p = [o[c] + half[c] + t * d[c] for c in range(3)]
        fu = np.where(k0, p[1], p[0])
        fv = np.where(k2, p[1], p[2])
        byte = [q.view(np.uint8) for q in plus]
        face = np.where(k0, byte[0], np.where(k2, 4 + byte[2], 2 + byte[1]))
        rho, half_px = (self.rho if box.rho is None else np.float32(box.rho)), np.float32(0.5)
        mx = _gather(box.faces, 0, face) + np.minimum(np.maximum(fu * rho - half_px, 0), _gather(box.faces, 2, face))
        my = _gather(box.faces, 1, face) + np.minimum(np.maximum(fv * rho - half_px, 0), _gather(box.faces, 3, face))
        if box.sky is not None:
            sky = win & (face == 5)
            t = np.where(sky, np.float32(np.inf), t)
            ox, oy, sw, sh = (np.float32(v) for v in box.sky)
            horizontal = np.sqrt(d[0] * d[0] + d[1] * d[1])
            sx = ox + (np.arctan2(d[0], d[1]) * np.float32(0.5 / np.pi) + np.float32(0.5)) * sw
            sy = oy + np.clip(np.arctan2(d[2], horizontal) * np.float32(2.0 / np.pi), 0, 1) * sh
            mx, my = np.where(sky, sx, mx), np.where(sky, sy, my)
        np.copyto(depth, t, where=win)
        np.copyto(hits.map_x[v0:v1, u0:u1], mx, where=win)
        np.copyto(hits.map_y[v0:v1, u0:u1], my, where=win)
        np.copyto(hits.dynamic[v0:v1, u0:u1], bool(box.dynamic), where=win)


def _gather(table: np.ndarray, column: int, face: np.ndarray) -> np.ndarray:
    """``table[face, column]`` for a uint8 face index image, as a 256-entry look-up table (faster than indexing)."""
    lut = np.zeros(256, np.float32)
    lut[: len(table)] = table[:, column]
    return cv2.LUT(face, lut)


def shade(atlas: np.ndarray, hits: Hits) -> np.ndarray:
    """Gather the colours of the hit texels (bilinear), (H, W, 3) uint8 like the atlas."""
    return cv2.remap(atlas, hits.map_x, hits.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def box_hits(centres: np.ndarray, rotations: np.ndarray, half: np.ndarray, poses_c2w: np.ndarray,
             intrinsics, width: int, height: int) -> np.ndarray:
    """Which pixels' rays hit one moving box in front of the camera, per pose: (N, height·width) bool.

    ``centres`` (N, 3) and ``rotations`` (N, 3, 3) give the box at each of the
    N poses.  Occlusion by other geometry is ignored: this is the cheap
    low-resolution estimate used to tune the walkers' paths.
    """
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    xs = np.broadcast_to(((np.arange(width) - cx) / fx)[None, :], (height, width)).ravel().astype(np.float32)
    ys = np.broadcast_to(((np.arange(height) - cy) / fy)[:, None], (height, width)).ravel().astype(np.float32)
    m = (np.swapaxes(rotations, -1, -2) @ poses_c2w[:, :3, :3]).astype(np.float32)  # (N, 3, 3) camera → box
    o = np.einsum("nji,nj->ni", rotations, poses_c2w[:, :3, 3] - centres).astype(np.float32)  # (N, 3)
    tn = tf = None
    with np.errstate(divide="ignore", invalid="ignore"):
        for c in range(3):
            d = m[:, c, 0, None] * xs + m[:, c, 1, None] * ys + m[:, c, 2, None]  # (N, P)
            inv = np.float32(1.0) / d
            ta = (np.float32(-half[c]) - o[:, c, None]) * inv
            tb = (np.float32(half[c]) - o[:, c, None]) * inv
            lo, hi = np.minimum(ta, tb), np.maximum(ta, tb)
            tn = lo if tn is None else np.maximum(tn, lo)
            tf = hi if tf is None else np.minimum(tf, hi)
    return (tn <= tf) & (tf > EPS)
