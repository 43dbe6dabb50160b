"""The backend: one global BA over all keyframes after the frontend is done.

It reuses every edge the frontend matched (their targets are cached at 1/8
resolution, so no image is needed): radius and proximity edges of every
window, now optimised jointly with frame 0 as the only fixed pose.
θ stays frozen (DROID-W: "θ is frozen during the final global BA").
"""

from __future__ import annotations

import dataclasses

import torch

from droidw_cli.config import BackendConfig
from droidw_cli.slam.frontend import Frontend
from droidw_cli.slam.optimizer import run_window


def global_ba(frontend: Frontend, cfg: BackendConfig) -> float:
    """Run the global BA in place on the frontend's buffer; returns the final cost."""
    n = len(frontend.buffer)
    if not frontend.initialised or n < 3 or not cfg.enable or cfg.iters <= 0:
        return float("nan")
    pairs = frontend.cache.pairs()
    edges = frontend.cache.edge_set(pairs)
    params = frontend.params
    optimize_theta = not params.uncertainty.freeze_in_global
    if params.optimize_focal != "none":
        params = dataclasses.replace(params, optimize_focal="none")  # calibration is settled by now
    with torch.no_grad():
        return run_window(frontend.backend, frontend.buffer, 0, n, edges, params, frontend.shared,
                          cfg.iters, fixed=1, optimize_theta=optimize_theta)
