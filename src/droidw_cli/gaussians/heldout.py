"""Scores and pictures of the map on the held-out frames (input frames no step was fitted to).

Per held-out frame, at its tracked pose: the static map alone and the composite (static map plus the object
Gaussians of the nearest keyframe, ADD-SLAM Eq. 16).  Scores (``losses.psnr`` / ``losses.ssim``):

* static pixels (not in the frame's dynamic mask): the static map against the frame;
* all pixels: the composite against the frame;
* dynamic pixels: the static map alone and the composite, over every held-out frame and over those within
  ``NEAR`` frames of a keyframe (the objects have no motion model, so they fit best near their keyframes).

Each frame's picture ``views/frame_NNNNNN.png`` is the real frame, the static map and the composite side by side.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import torch

from droidw_cli.gaussians.dynamic_map import at_time
from droidw_cli.gaussians.inputs import MapInputs
from droidw_cli.gaussians.losses import psnr, ssim
from droidw_cli.gaussians.model import Gaussians
from droidw_cli.gaussians.static_map import camera

NEAR = 2  # frames: "near a keyframe"


def _mean(values) -> float | None:
    v = np.asarray([x for x in values if x == x], dtype=np.float64)
    return round(float(v.mean()), 3) if v.size else None


def _label(img: np.ndarray, text: str) -> np.ndarray:
    out = np.ascontiguousarray(img)
    cv2.putText(out, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def evaluate(inputs: MapInputs, static: Gaussians, dynamic: Gaussians, rasteriser, views_dir: Path | None) -> dict:
    """Scores over the held-out frames (module docstring); writes the pictures into ``views_dir`` when given."""
    h = inputs.heldout
    kf_index = inputs.keyframes.index
    rows = []
    for j in range(len(h)):
        cam = camera(inputs, h, j)
        with torch.no_grad():
            alone = rasteriser.render(static, cam).colour.clamp(0, 1).numpy()
            objs = at_time(dynamic, inputs.keyframes.timestamps, float(h.timestamps[j]))
            comp = alone if len(objs) == 0 else rasteriser.render(Gaussians.cat([static, objs]), cam).colour.clamp(0, 1).numpy()
        real, dyn = h.images[j], h.dynamic[j]
        near = int(np.min(np.abs(kf_index - h.index[j]))) <= NEAR
        rows.append({"frame": int(h.index[j]), "near_keyframe": bool(near),
                     "psnr_static_pixels": psnr(alone, real, ~dyn), "ssim_static_pixels": ssim(alone, real, ~dyn),
                     "psnr_all": psnr(comp, real), "ssim_all": ssim(comp, real),
                     "psnr_dynamic_static_only": psnr(alone, real, dyn), "psnr_dynamic_composite": psnr(comp, real, dyn)})
        if views_dir is not None:
            panels = [_label((x * 255).round().astype(np.uint8), t)
                      for x, t in ((real, "frame"), (alone, "static map"), (comp, "composite"))]
            cv2.imwrite(str(views_dir / f"frame_{int(h.index[j]):06d}.png"), np.concatenate(panels, 1)[..., ::-1])
    near = [r for r in rows if r["near_keyframe"]]
    summary = {key: _mean(r[key] for r in rows) for key in
               ("psnr_static_pixels", "ssim_static_pixels", "psnr_all", "ssim_all", "psnr_dynamic_static_only",
                "psnr_dynamic_composite")}
    summary["near_keyframe"] = {"frames": len(near),
                                "psnr_dynamic_static_only": _mean(r["psnr_dynamic_static_only"] for r in near),
                                "psnr_dynamic_composite": _mean(r["psnr_dynamic_composite"] for r in near)}
    return {"frames": len(rows), "mask_source": inputs.mask_source, "mean": summary,
            "per_frame": [{k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()} for r in rows]}
