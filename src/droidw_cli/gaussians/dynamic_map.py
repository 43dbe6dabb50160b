"""Temporal object Gaussians (ADD-SLAM Eq. 15-16): per tracked object, its own Gaussians at each keyframe.

G_d^id(t) holds the Gaussians of object ``id`` at keyframe time t, with no motion model across time
(Eq. 15).  At keyframe j every pixel of the object's mask that has a depth gets a Gaussian (back-projected as
for the static map, on the same pixel grid).  The scene at t is the static map plus
every object's Gaussians of t (Eq. 16); the object Gaussians of keyframe j are fitted to its dynamic pixels
(the object masks) with the static map fixed: ``object_steps`` Adam steps of the static map's colour and
depth losses, each rendering only the window around the objects (a crop of the camera).  Every keyframe
gets its Gaussians; a short budget thins out the steps evenly (:class:`~.static_map.Pace`).
"""

from __future__ import annotations

import numpy as np
import torch
from tqdm import tqdm

from droidw_cli.gaussians.inputs import MapInputs
from droidw_cli.gaussians.losses import colour_loss, depth_loss
from droidw_cli.gaussians.model import Gaussians
from droidw_cli.gaussians.optim import GaussianAdam
from droidw_cli.gaussians.params import MapParams
from droidw_cli.gaussians.static_map import Deadline, Pace, backproject, camera, stride_grid

PAD = 8  # pixels of context around the objects' window


def window(mask: np.ndarray) -> tuple[int, int, int, int]:
    """(y0, x0, h, w) of the box around ``mask``, grown by :data:`PAD` and clipped to the image."""
    v, u = np.nonzero(mask)
    y0, x0 = max(0, int(v.min()) - PAD), max(0, int(u.min()) - PAD)
    y1, x1 = min(mask.shape[0], int(v.max()) + PAD + 1), min(mask.shape[1], int(u.max()) + PAD + 1)
    return y0, x0, y1 - y0, x1 - x0


def fit_objects(inputs: MapInputs, static: Gaussians, params: MapParams, rasteriser, deadline: Deadline,
                progress: bool, scene_depth: float) -> tuple[Gaussians, dict]:
    """The temporal Gaussians of every object at every keyframe (``t``, ``object_id`` set) and a summary."""
    kf = inputs.keyframes
    parts, steps, ended, fitted = [], 0, "steps", 0
    todo = [j for j in range(len(kf)) if (kf.object_ids[j] >= 0).any()]
    fixed = static.detached()
    pace = Pace(deadline, 1.0)
    for n_done, j in enumerate(tqdm(todo, desc="objects", unit="keyframe", disable=not progress, dynamic_ncols=True)):
        ids = kf.object_ids[j]
        pick = (ids >= 0) & (kf.depth[j] > 0)
        if not pick.any():
            continue
        pick &= stride_grid(inputs.size, params.init_stride)
        if not pick.any():
            continue
        g = backproject(inputs, kf, j, pick, params.init_stride, params.init_sigma, params.init_opacity)
        v, u = np.nonzero(pick)
        g.t = torch.full((len(g),), float(kf.timestamps[j]), dtype=torch.float64)
        g.object_id = torch.as_tensor(ids[v, u].astype(np.int64))
        y0, x0, h, w = window(ids >= 0)
        cam = camera(inputs, kf, j).crop(y0, x0, h, w)
        target = torch.as_tensor(kf.images[j][y0:y0 + h, x0:x0 + w])
        depth = torch.as_tensor(kf.depth[j][y0:y0 + h, x0:x0 + w])
        dyn = torch.as_tensor(ids[y0:y0 + h, x0:x0 + w] >= 0)
        opt = GaussianAdam(g, {"means": params.lr_position * scene_depth, "dc": params.lr_colour,
                               "opacity_logits": params.lr_opacity, "log_scales": params.lr_scale,
                               "quats": params.lr_rotation})
        for _ in range(params.object_steps):
            if pace.behind((n_done + 1) / len(todo)):
                ended = "time budget"
                break
            out = rasteriser.render(Gaussians.cat([fixed, opt.g]), cam)
            loss = colour_loss(out.colour, target, dyn, params.ssim_weight)
            loss = loss + params.depth_weight * depth_loss(out.depth, depth, dyn & (depth > 0), scene_depth)
            loss.backward()
            opt.step()
            steps += 1
        keep = torch.sigmoid(opt.g.opacity_logits.detach()) >= params.prune_opacity
        parts.append(opt.g.select(keep))
        fitted += 1
    dynamic = Gaussians.cat(parts) if parts else Gaussians.empty()
    if not parts:
        dynamic.t = torch.zeros(0, dtype=torch.float64)
        dynamic.object_id = torch.zeros(0, dtype=torch.int64)
    objects = sorted({int(i) for i in dynamic.object_id.tolist()}) if len(dynamic) else []
    return dynamic, {"steps": steps, "ended": ended, "keyframes": fitted, "keyframes_with_objects": len(todo),
                     "objects": objects}


def at_time(dynamic: Gaussians, timestamps: np.ndarray, t: float) -> Gaussians:
    """The object Gaussians of the keyframe nearest to time t (Eq. 16's G_d(t), no motion model)."""
    if len(dynamic) == 0 or len(timestamps) == 0:
        return Gaussians.empty()
    nearest = float(timestamps[int(np.argmin(np.abs(np.asarray(timestamps) - t)))])
    return dynamic.select(torch.isclose(dynamic.t, torch.tensor(nearest, dtype=torch.float64)))
