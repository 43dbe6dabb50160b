"""Reports of an evaluation: a text table, a JSON-ready dict and a top-view plot."""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from droidw_cli.eval.metrics import AteResult, RpeResult
from droidw_cli.io.trajectory import Trajectory

ALIGN_NAMES = {"sim3": "Sim(3) Umeyama", "se3": "SE(3) Umeyama", "none": "none"}


@dataclass(frozen=True)
class EvalInfo:
    """What was compared and how (for the report header)."""

    gt_path: str
    est_path: str
    gt_poses: int
    est_poses: int
    max_diff: float
    by_index: bool = False


def format_text(info: EvalInfo, ate: AteResult, rpe: RpeResult | None = None) -> str:
    """A human-readable table of the ATE (and RPE), metres."""
    how = "by index" if info.by_index else f"by timestamp, max diff {info.max_diff:g} s"
    lines = [
        f"ground truth  {info.gt_path} ({info.gt_poses} poses)",
        f"estimate      {info.est_path} ({info.est_poses} poses)",
        f"matched       {ate.matches} poses ({how})",
        f"alignment     {ALIGN_NAMES.get(ate.align, ate.align)}",
    ]
    if ate.align == "sim3":
        lines.append(f"scale         {ate.scale:.6f}")
    lines.append("")
    lines.append("ATE (translation, m)")
    lines += _stat_rows(ate.stats.as_dict())
    if rpe is not None:
        lines.append("")
        lines.append(f"RPE (translation, m, delta {rpe.delta} frames, {rpe.stats.count} pairs)")
        lines += _stat_rows(rpe.stats.as_dict())
    return "\n".join(lines)


def _stat_rows(stats: dict[str, float | int]) -> list[str]:
    return [f"  {name:<8}{stats[name]:.6f}" for name in ("rmse", "mean", "median", "std", "min", "max")]


def to_json_dict(info: EvalInfo, ate: AteResult, rpe: RpeResult | None = None) -> dict:
    """A JSON-serialisable summary (plain floats, ints, strings and lists)."""
    ate_stats = ate.stats.as_dict()
    ate_stats.pop("count")
    out: dict = {
        "gt": info.gt_path,
        "est": info.est_path,
        "gt_poses": info.gt_poses,
        "est_poses": info.est_poses,
        "association": "index" if info.by_index else "timestamp",
        "max_diff": None if info.by_index else float(info.max_diff),
        "matches": int(ate.matches),
        "align": ate.align,
        "scale": float(ate.scale),
        "rotation": np.asarray(ate.rotation, dtype=float).tolist(),
        "translation": np.asarray(ate.translation, dtype=float).tolist(),
        "ate": ate_stats,
        "rpe": None,
    }
    if rpe is not None:
        rpe_stats = rpe.stats.as_dict()
        out["rpe"] = {"delta": rpe.delta, "pairs": rpe_stats.pop("count"), **rpe_stats}
    return out


def top_view_axes(points: np.ndarray) -> tuple[int, int]:
    """The two coordinate axes along which ``points`` (N, 3) extend most (the 'top view' plane)."""
    extent = np.ptp(np.asarray(points, dtype=np.float64), axis=0)
    a, b = sorted(np.argsort(-extent, kind="stable")[:2].tolist())
    return int(a), int(b)


def plot_top_view(path: str | Path, gt: Trajectory, est: Trajectory, ate: AteResult) -> None:
    """Write a PNG with the ground truth and the aligned estimate seen from 'above', atomically.

    'Above' is along the axis of least ground-truth extent (z for TUM/EuRoC
    motion-capture worlds, y for KITTI camera worlds).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    path = Path(path)
    gt_xyz = gt.positions
    est_xyz = ate.transform.apply_points(est.positions)
    a, b = top_view_axes(gt_xyz)
    names = "xyz"
    fig = Figure(figsize=(7, 6), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    ax.plot(gt_xyz[:, a], gt_xyz[:, b], "-", color="0.35", lw=1.5, label="ground truth")
    ax.plot(est_xyz[:, a], est_xyz[:, b], "-", color="tab:blue", lw=1.0, label=f"estimate ({ate.align} aligned)")
    ax.plot(gt_xyz[:1, a], gt_xyz[:1, b], "o", color="0.35", ms=5)
    ax.plot(est_xyz[:1, a], est_xyz[:1, b], "o", color="tab:blue", ms=4)
    ax.set_xlabel(f"{names[a]} [m]")
    ax.set_ylabel(f"{names[b]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    title = f"ATE RMSE {ate.rmse:.4f} m, {ate.matches} poses"
    if ate.align == "sim3":
        title += f", scale {ate.scale:.4f}"
    ax.set_title(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fig.savefig(fh, format="png")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
