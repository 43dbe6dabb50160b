"""A ``droidw map`` folder in rerun: the Gaussians as ellipsoids.

* ``world/gaussians/static``: every static Gaussian as a solid ellipsoid (static), centred on its mean,
  with half-axes of one standard deviation along its rotated axes and its SH degree-0 colour;
* ``world/gaussians/objects``: each keyframe's object Gaussians (``dynamic.ply``) at that keyframe's time.

Ellipsoids, not splats: rerun's Gaussian-splat archetype is not stable, and a standard 3DGS viewer reads
``static.ply`` directly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from droidw_cli.errors import InputError


def find_map(run_dir: Path, map_dir: Path | None) -> Path | None:
    """``map_dir`` (which must hold static.ply), else ``RUN/map`` when it has one, else None."""
    if map_dir is not None:
        if not (map_dir / "static.ply").is_file():
            raise InputError(f"{map_dir}: no static.ply; run `droidw map RUN --out {map_dir}` first")
        return map_dir
    default = run_dir / "map"
    return default if (default / "static.ply").is_file() else None


def _ellipsoids(g):
    import rerun as rr
    import torch

    q = (g.quats / g.quats.norm(dim=1, keepdim=True).clamp_min(1e-12)).numpy()
    rgb = (torch.clamp(g.rgb, 0, 1).numpy() * 255).astype(np.uint8)
    return rr.Ellipsoids3D(centers=g.means.numpy(), half_sizes=np.exp(g.log_scales.numpy()),
                           quaternions=q[:, [1, 2, 3, 0]], colors=rgb, fill_mode="solid")


def log_map(rec, map_dir: Path, t0: float, kf_times: np.ndarray, kf_index: np.ndarray) -> int:
    """Log the map's Gaussians into ``rec``; returns how many (static and object ones)."""
    from droidw_cli.gaussians.ply import read_ply

    try:
        static = read_ply(map_dir / "static.ply")
        dynamic = read_ply(map_dir / "dynamic.ply") if (map_dir / "dynamic.ply").is_file() else None
    except (OSError, ValueError, KeyError) as exc:
        raise InputError(f"{map_dir}: cannot read the Gaussian map ({exc})") from None
    rec.log("world/gaussians/static", _ellipsoids(static), static=True)
    total = len(static)
    if dynamic is not None and len(dynamic):
        for t in np.unique(dynamic.t.numpy()):
            k = int(np.argmin(np.abs(kf_times - t)))
            rec.set_time("frame", sequence=int(kf_index[k]))
            rec.set_time("time", duration=float(t) - t0)
            rec.log("world/gaussians/objects", _ellipsoids(dynamic.select(dynamic.t == t)))
        total += len(dynamic)
    return total
