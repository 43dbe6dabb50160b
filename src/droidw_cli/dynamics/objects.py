"""Dynamic objects of a finished run: final masks, ids over the keyframes, centres and 3D centroids.

After the global BA (:func:`finish`):

1. The output dynamic mask M_k of every keyframe (``keyframes.npz``
   ``dynamic``, left out of the static map).  The in-loop masks stay what BA
   zeroed; they are conservative (the epipolar ones are grown by
   ``epipolar_dilate`` cells and cover about three times the movers: mask IoU
   0.24-0.35 on the synthetic presets), so with scene consistency on, M_k is
   the union of the consistency masks of keyframe k under the final poses
   against up to ``consistency_sources`` keyframes before it and, separately,
   against as many after it (the online check only had predecessors), and its
   last in-loop consistency mask.  Each side on its own, because a mover
   that overlaps its own earlier position is often flagged by one side only,
   and the views' "at least half" rule of one test over both sides then
   drops it (mask IoU 0.69 against 0.76 on rotate, 0.80 against 0.84 on
   stopgo, the same precision).  Without scene consistency and without a depth
   sensor, M_k is the monocular motion mask of the kept short edges' flow under
   the final poses (:mod:`~droidw_cli.dynamics.posthoc`; the in-loop epipolar
   record had mask IoU 0.20-0.32); with a sensor, the in-loop record.
2. Object ids (:class:`~droidw_cli.dynamics.tracker.DynamicObjectTracker`:
   association by the overlap of predicted masks, ADD-SLAM's rules for weak
   matches) over the keyframes in order.  Keyframes lie several frames apart,
   so an object's previous centre c (keyframe j) is first carried into the new
   keyframe k by the image motion of its world centroid X̄, moved on to X̄' at
   its constant world velocity from the two keyframes before when it has them:
   c' = c + Π(G_k X̄') − Π(G_j X̄); a second hypothesis keeps X̄' = X̄ (a
   velocity from a bad centroid must not lose the object).  The predicted
   depth is δ' = δ · z_k(X̄') / z_j(X̄).  Centroids of objects the tracker marks
   occluded are not used for the velocity.  The depth reaches the tracker
   only where it is a sensor's (``sensor_depth``): BA's depth on movers is
   what the zeroed confidence left, and with it the ids switched 15-17 times
   per walker on the monocular presets against 3-6 without.  Monocular, the
   first prediction of each object of keyframe k − 1 is its pixels carried
   into k by the recorded flow (:func:`_carry`; the pixels of k whose match
   in k − 1 by the edge (k, k − 1) lies on the object): it follows each
   walker of a pile, where a shifted mask cuts across them; it replaces the
   centre hypotheses of the objects it carries (id switches rotate 15 → 9,
   stopgo 5 → 3, wobble 7 → 5, walk 2; with the centre hypotheses after it:
   wobble 7; carried forward by the edge (k − 1, k): 11, 3, 8, 3).  With a depth sensor
   the depth split does better without it (rotate 8 against 11, wobble 1
   against 3).  With a depth sensor the tracker also gets each pixel's place
   on the floor, (X·e₁, X·e₂) for its world point X and a basis e₁, e₂ of the
   plane normal to the up direction u (the mean of the cameras' −y axes:
   cameras held upright; no floor cue when that mean is shorter than 0.5),
   and each object's X̄' there: walkers that touch in the image stand apart
   on the floor, so a track claims the components near its X̄' and a shared
   component is split by the distance on the floor unless the claimers stand
   in one place (id switches of the RGB-D captures, seeds 1-3: 36 → 21; seed
   4, held out: 10 → 5).  An active
   object that finds no mask at c' is *propagated* from c': the 3 × 3 pixels
   at c' prompt the segmenter when the new keyframe there still looks like
   the object (depth within ``depth_rel_tol`` of its median depth δ, colour
   within max(``color_tol``, ``color_spread`` σ) of its mean colour μ), and
   the grown region is kept when its area is within ``track_growth``× of the
   object's last area either way.
   With ``track_backtrack``, each new track then labels the keyframes before
   its birth (:mod:`~droidw_cli.dynamics.backtrack`: moved back at its image
   velocity; the recorded flow on a mover follows the background, 3 grid px
   the wrong way on the walk, so it carries the camera's motion, not the
   walker's).
3. Per object and keyframe of the final id maps: the image centre (inscribed circle, mapped to the
   input image's pixels by the caller) and the world centroid

       X̄ = (1/|O|) Σ_{p∈O} G_k⁻¹ · (D_p K⁻¹ p̃),

   with D the observed depth (the sensor's in RGB-D mode, else 1/d from BA).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import Tensor

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics.backtrack import backtrack
from droidw_cli.dynamics.inloop import KeyframeMasks
from droidw_cli.dynamics.refine import object_centre
from droidw_cli.dynamics.tracker import DynamicObjectTracker
from droidw_cli.geometry.poses import invert, to_matrix

#: columns of :attr:`DynamicRecord.table`
TABLE_COLUMNS = ("keyframe", "id", "cx", "cy", "x", "y", "z", "area")


@dataclass(frozen=True)
class DynamicRecord:
    """Per keyframe: ``masks`` (K, h, w) bool, ``ids`` (K, h, w) int16 (−1: no object; int32 when an id
    passes 32767 — a keyframe map costs 6 KB instead of 12 KB, and keyframes.npz stores int32 either way);
    ``table`` (M, 8) float64 rows of :data:`TABLE_COLUMNS` (centre in grid px, centroid in world metres)."""

    masks: np.ndarray
    ids: np.ndarray
    table: np.ndarray
    masked: np.ndarray | None = None  # (K, h, w) bool: masks ∪ the in-loop record (what BA zeroed; the static map's exclusion)


def _depth(disp: Tensor) -> Tensor:
    return torch.where(disp > 0, 1.0 / disp.clamp(min=1e-6), torch.zeros_like(disp))


def _stats(image: Tensor, depth: Tensor, mask: Tensor) -> tuple[Tensor, float, float] | None:
    """(mean colour μ, RMS spread σ, median depth δ) of the object's pixels with known depth."""
    ok = mask & (depth > 0)
    if not bool(ok.any()):
        return None
    cols = image[ok]
    mu = cols.mean(0)
    return mu, float(((cols - mu) ** 2).sum(-1).mean().sqrt()), float(depth[ok].median())


def _project(x: np.ndarray, c2w: np.ndarray, kk: Tensor) -> np.ndarray | None:
    """Grid pixel and depth (u, v, z) of world point x in a camera (None behind it)."""
    p = c2w[:3, :3].T @ (x - c2w[:3, 3])
    if p[2] <= 1e-3:
        return None
    fx, fy, cx, cy = (float(v) for v in kk)
    return np.array([fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy, p[2]])


def _predict(history: dict[int, list[tuple[int, np.ndarray]]], tracker: DynamicObjectTracker, times: np.ndarray,
             k: int, c2w: np.ndarray, kk: Tensor
             ) -> tuple[dict[int, list[tuple[float, float]]], dict[int, float], dict[int, np.ndarray]]:
    """Centre hypotheses c' (grid px) and depth δ' in keyframe k (camera-to-world poses ``c2w`` (K, 4, 4))
    of each live object with a world centroid (see step 2).

    c' = c + Π_k(X̄') − Π_j(X̄): the previous centre c (keyframe j) moved by the image motion of
    the centroid, because the inscribed-circle centre and the centroid's projection differ;
    hypotheses: X̄' moved at constant world velocity, and X̄' = X̄ (camera motion only).
    δ' = δ · z_k(X̄') / z_j(X̄) for the median depth δ (constant velocity).  Also X̄' itself (the first
    hypothesis) per object.
    """
    centres, depths, centroids = {}, {}, {}
    for tid, obj in tracker.live().items():
        seen = history.get(tid)
        if not seen:
            continue
        k1, x1 = seen[-1]
        moved = [x1]
        if len(seen) >= 2 and times[k1] > times[seen[-2][0]]:
            k0, x0 = seen[-2]
            moved.insert(0, x1 + (x1 - x0) * (times[k] - times[k1]) / (times[k1] - times[k0]))
        centroids[tid] = moved[0]
        a = _project(x1, c2w[k1], kk)
        hyps = []
        for x in moved:
            b = _project(x, c2w[k], kk)
            if a is None or b is None:
                continue
            hyps.append((float(obj.centre[0] + b[0] - a[0]), float(obj.centre[1] + b[1] - a[1])))
            if obj.depth > 0 and tid not in depths:
                depths[tid] = float(obj.depth * b[2] / a[2])
        if hyps:
            centres[tid] = hyps
    return centres, depths, centroids


def _propagate(masks: KeyframeMasks, mask: Tensor, image: Tensor, depth: Tensor, tracker: DynamicObjectTracker,
               stats: dict[int, tuple[Tensor, float, float]], cfg: DynamicsConfig,
               predicted: dict[int, list[tuple[float, float]]], focal: tuple[float, float]) -> Tensor:
    """``mask`` plus the objects grown from the (predicted) centres of active tracks it misses (``focal``:
    the grid's (f_x, f_y), for the grower's slant limit)."""
    if masks.segmenter is None or not tracker.active:
        return mask
    h, w = mask.shape
    p = masks.params
    out = mask.clone()
    for tid, obj in sorted(tracker.active.items()):  # a handful of objects
        centre = predicted.get(tid, [obj.centre])[0]
        x, y = int(round(centre[0])), int(round(centre[1]))
        if not (0 <= x < w and 0 <= y < h) or bool(mask[y, x]) or tid not in stats:
            continue
        mu, sigma, delta = stats[tid]
        d = float(depth[y, x])
        colour_ok = float((image[y, x] - mu).norm()) <= max(p.color_tol, p.color_spread * sigma)
        if d <= 0 or abs(d - delta) > p.depth_rel_tol * delta or not colour_ok:
            continue
        seed = torch.zeros_like(mask)  # a 3 × 3 prompt at the centre (a seed needs min_seed_area pixels)
        seed[max(0, y - 1):y + 2, max(0, x - 1):x + 2] = True
        grown = masks.segmenter.segment(seed, image, depth, focal=focal).mask & ~out
        area = int(grown.sum())
        if obj.area / cfg.track_growth <= area <= obj.area * cfg.track_growth:
            out |= grown
    return out


def _carry(masks: KeyframeMasks, k: int, prev: np.ndarray | None) -> dict[int, np.ndarray]:
    """The objects of keyframe k − 1 (id map ``prev``) carried into keyframe k by the recorded flow, by id.

    With the edge (k, k − 1): each pixel of k takes the id at its match p* in k − 1 (no holes, and an
    occluder's pixels follow the occluder).  Else with the edge (k − 1, k): each object pixel moves to
    its target p*, the holes closed (3 × 3).  Neither: nothing."""
    if prev is None or not (prev >= 0).any():
        return {}
    back = masks.match_index(k, k - 1)
    if back is not None:  # each pixel of k takes the id at its match in k − 1
        pulled = np.where(back >= 0, prev.reshape(-1)[np.maximum(back, 0)], -1)
        return {int(t): pulled == t for t in np.unique(pulled[pulled >= 0])}
    fwd = masks.match_index(k - 1, k)
    if fwd is None:
        return {}
    ok = (prev >= 0) & (fwd >= 0)
    out = {}
    kernel = np.ones((3, 3), np.uint8)
    for tid in np.unique(prev[ok]):  # a handful of objects
        m = np.zeros(prev.size, np.uint8)
        m[fwd[ok & (prev == tid)]] = 1
        out[int(tid)] = cv2.morphologyEx(m.reshape(prev.shape), cv2.MORPH_CLOSE, kernel).astype(bool)
    return out


def final_pass(masks: KeyframeMasks, poses_w2c: Tensor, disps_obs: Tensor, intrinsics: Tensor,
               cfg: DynamicsConfig, sensor_depth: bool = False) -> list[Tensor]:
    """Step 1: the output dynamic mask of every keyframe, (h, w) bool each.

    With scene consistency on: the union of the consistency masks under the final poses against the
    keyframes before and against those after (each side tested on its own) and the keyframe's last
    in-loop consistency mask.  Without it: monocular (not ``sensor_depth``), the motion masks of
    :func:`~droidw_cli.dynamics.posthoc.motion_masks`; else the in-loop record (epipolar masks).
    """
    n = len(masks)
    if not masks.consistency:
        if masks.keep_flow and not sensor_depth:  # monocular: the flow the final poses cannot explain
            return masks.output_masks(poses_w2c[:n], disps_obs[:n], intrinsics)
        return [masks.masks[k].clone() for k in range(n)]
    g = poses_w2c[:n].detach().float().cpu()
    d = disps_obs[:n].detach().float().cpu()
    m = cfg.consistency_sources
    out = []
    for k in range(n):
        mask = masks.current[k].clone()
        for sources in (list(range(max(0, k - m), k)), list(range(k + 1, min(n, k + 1 + m)))):
            objects = masks.detect(k, g, d, intrinsics, sources)
            if objects is not None:
                mask |= objects.mask.cpu()
        out.append(mask)
    return out


def _on_ground(points: np.ndarray, up: np.ndarray) -> np.ndarray:
    """World points (…, 3) on the plane normal to ``up``: (X·e₁, X·e₂), e₁ and e₂ an orthonormal basis of it."""
    e1 = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 0.0, 1.0])
    e1 /= np.linalg.norm(e1)
    return points @ np.stack([e1, np.cross(up, e1)], 1)


#: the cameras' −y axes must agree this well (length of their mean) for the floor cue: cameras held upright
UPRIGHT = 0.5


def _up(c2w: np.ndarray) -> np.ndarray | None:
    """The world's up direction as the mean of the keyframe cameras' −y axes (cameras held upright); None
    when the mean is shorter than :data:`UPRIGHT` (a camera turned on its side or upside down: no floor cue)."""
    up = -c2w[:, :3, 1].mean(0) if len(c2w) else np.zeros(3)
    norm = float(np.linalg.norm(up))
    return up / norm if norm >= UPRIGHT else None


def _world(rays: np.ndarray, depth: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World points G⁻¹ · (D_p K⁻¹ p̃) of pixels given by their rays (…, 3) and depths (…)."""
    return (rays * depth[..., None]) @ c2w[:3, :3].T + c2w[:3, 3]


def _centroid(mask: np.ndarray, depth: np.ndarray, rays: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """World centroid X̄ of an object's pixels with known depth (NaN without any), step 3."""
    ok = mask & (depth > 0)
    if not ok.any():
        return np.full(3, np.nan)
    return _world(rays[ok], depth[ok], c2w).mean(0)


def _table(ids: np.ndarray, disps: Tensor, rays: np.ndarray, c2w: np.ndarray) -> np.ndarray:
    """Step 3: the rows of :data:`TABLE_COLUMNS` of every object in every keyframe of the id maps."""
    rows = []
    for k, lab in enumerate(ids):
        depth = _depth(disps[k]).numpy().astype(np.float64)
        for tid in np.unique(lab[lab >= 0]):
            mask = lab == tid
            cx, cy = object_centre(mask)
            rows.append([k, int(tid), cx, cy, *_centroid(mask, depth, rays, c2w[k]), int(mask.sum())])
    return np.array(rows, dtype=np.float64).reshape(-1, len(TABLE_COLUMNS))


def track_objects(masks: KeyframeMasks, poses_w2c: Tensor, disps_obs: Tensor, intrinsics: Tensor,
                  cfg: DynamicsConfig, dynamic: list[Tensor] | None = None, sensor_depth: bool = False) -> DynamicRecord:
    """Steps 2-3: propagation, ids, and per object and keyframe its centre and world centroid.

    ``dynamic``: the masks to track (step 1's, default: the in-loop record ``masks.masks``).
    ``sensor_depth``: ``disps_obs`` is a depth sensor's; only then does the tracker use depth.
    """
    dynamic = [m.clone() for m in (masks.masks if dynamic is None else dynamic)]
    n = len(masks)
    h, w = masks.grid
    g = poses_w2c[:n].detach().double().cpu()
    d = disps_obs[:n].detach().float().cpu()
    kk = intrinsics.detach().double().cpu()
    tracker = DynamicObjectTracker(border=cfg.track_border, max_growth=cfg.track_growth, max_jump=cfg.track_jump,
                                   min_area=masks.params.min_object_area, min_new=cfg.track_min_new)
    ids = np.full((n, h, w), -1, dtype=np.int16)  # int32 only once an id needs it (see DynamicRecord)
    stats: dict[int, tuple[Tensor, float, float]] = {}
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    rays = np.stack([(gx - float(kk[2])) / float(kk[0]), (gy - float(kk[3])) / float(kk[1]), np.ones_like(gx)], -1)
    c2w = to_matrix(invert(g)) if n else np.zeros((0, 4, 4))
    history: dict[int, list[tuple[int, np.ndarray]]] = {}  # id → (keyframe, world centroid) so far
    times = np.asarray(masks.times, dtype=np.float64)
    up = _up(c2w) if sensor_depth else None
    focal = (float(kk[0]), float(kk[1]))
    for k in range(n):
        depth = _depth(d[k])
        predicted, predicted_depth, centroids = _predict(history, tracker, times, k, c2w, kk)
        mask = _propagate(masks, dynamic[k], masks.image(k), depth, tracker, stats, cfg, predicted, focal)
        dynamic[k] = mask
        depth_np = depth.numpy().astype(np.float64)
        carried = _carry(masks, k, ids[k - 1] if k and not sensor_depth else None)
        if sensor_depth:
            ground, placed = None, None
            if up is not None:
                floor = _on_ground(_world(rays, depth_np, c2w[k]), up)
                ground = np.where((depth_np > 0)[..., None], floor, np.nan)  # (h, w, 2)
                placed = {tid: _on_ground(x, up) for tid, x in centroids.items()}
            objs = tracker.update(mask, predicted, depth_np, predicted_depth, masks.image(k).numpy(), carried,
                                  ground, placed)
        else:
            objs = tracker.update(mask, predicted, image=masks.image(k).numpy(), predicted_masks=carried)
        stats = {}
        for obj in objs:
            if obj.id > np.iinfo(ids.dtype).max:
                ids = ids.astype(np.int32)
            ids[k][obj.mask] = obj.id
            s = _stats(masks.image(k), depth, torch.from_numpy(obj.mask))
            if s is not None:
                stats[obj.id] = s
            if not obj.occluded:  # a partly hidden object's centroid is biased: not used for its motion
                centroid = _centroid(obj.mask, depth_np, rays, c2w[k])
                if np.isfinite(centroid).all():
                    history.setdefault(obj.id, []).append((k, centroid))
    stacked = torch.stack(dynamic).numpy() if n else np.zeros((0, h, w), dtype=bool)
    if cfg.track_backtrack:
        ids = backtrack(ids, stacked, times, masks.params.min_object_area)
    table = _table(ids, d, rays, c2w)
    return DynamicRecord(stacked, ids, table)


def finish(masks: KeyframeMasks, poses_w2c: Tensor, disps_obs: Tensor, intrinsics: Tensor,
           cfg: DynamicsConfig, sensor_depth: bool = False) -> DynamicRecord:
    """Final masks, object ids and per-keyframe object centres and centroids (see the module docstring).

    ``poses_w2c`` (K, 7), ``disps_obs`` (K, h, w) observed disparities, ``intrinsics`` (4,) of the grid.
    """
    dynamic = final_pass(masks, poses_w2c, disps_obs, intrinsics, cfg, sensor_depth)
    rec = track_objects(masks, poses_w2c, disps_obs, intrinsics, cfg, dynamic, sensor_depth)
    return DynamicRecord(rec.masks, rec.ids, rec.table, rec.masks | masks.stacked())
