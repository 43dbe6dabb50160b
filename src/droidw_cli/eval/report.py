"""Reports of an evaluation: a text table, a JSON-ready dict, evo's result file and evo's top-view plot."""

from __future__ import annotations

import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from droidw_cli.eval.metrics import AteResult, RpeResult
from droidw_cli.io.trajectory import Trajectory, atomic_write_bytes

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


def _atomic_write(path: Path, write) -> None:
    """Call ``write(binary file)`` on an in-memory buffer, then write it to ``path`` atomically."""
    buf = io.BytesIO()
    write(buf)
    atomic_write_bytes(path, buf.getvalue())


def _evo_plot_module():
    """``evo.tools.plot`` with matplotlib on the Agg backend (no window, works headless).

    evo applies its settings' ``plot_backend`` when the module is imported;
    droidw only ever writes files, so it asks for Agg whatever the settings say.
    """
    from evo.tools.settings import SETTINGS

    SETTINGS.plot_backend = "Agg"
    from evo.tools import plot

    import matplotlib.pyplot as plt

    plt.switch_backend("Agg")
    return plot, plt


def plot_top_view(path: str | Path, gt: Trajectory, est: Trajectory, ate: AteResult) -> None:
    """Write a PNG with evo's plotting, atomically: the ground truth (grey, dashed) and the
    aligned estimate coloured by its ATE, seen from 'above'.

    'Above' is along the axis of least ground-truth extent (z for TUM/EuRoC
    motion-capture worlds, y for KITTI camera worlds).  ``est`` is unused: the
    aligned, matched estimate comes from ``ate``.
    """
    if ate.evo_result is None:
        raise ValueError("plot_top_view needs an AteResult from evaluate_ate (with its evo result)")
    plot, plt = _evo_plot_module()
    from droidw_cli.eval.metrics import evo_trajectory

    a, b = top_view_axes(gt.positions)
    mode = plot.PlotMode("xyz"[a] + "xyz"[b])
    est_name = ate.evo_result.info["est_name"]
    aligned = ate.evo_result.trajectories[est_name]
    fig = plt.figure(figsize=(7, 6), dpi=100)
    try:
        ax = plot.prepare_axis(fig, mode)
        plot.traj(ax, mode, evo_trajectory(gt), "--", "gray", "ground truth")
        lo, hi = float(np.min(ate.errors)), float(np.max(ate.errors))
        plot.traj_colormap(ax, aligned, ate.errors, mode, min_map=lo, max_map=max(hi, lo + 1e-12), fig=fig)
        title = f"ATE RMSE {ate.rmse:.4f} m, {ate.matches} poses, {ALIGN_NAMES.get(ate.align, ate.align)}"
        if ate.align == "sim3":
            title += f", scale {ate.scale:.4f}"
        ax.set_title(title)
        _atomic_write(Path(path), lambda fh: fig.savefig(fh, format="png"))
    finally:
        plt.close(fig)


def save_results(path: str | Path, ate: AteResult, ref_name: str, est_name: str) -> None:
    """Write the ATE as evo's result file (a zip that ``evo_res`` reads), atomically.

    The same content as ``evo_ape ... --save_results``: info (title, label,
    ref_name, est_name), stats, the error array, timestamps, the alignment;
    the trajectories too when evo's ``save_traj_in_zip`` setting asks for them.
    """
    import copy

    from evo.tools import file_interface
    from evo.tools.settings import SETTINGS

    if ate.evo_result is None:
        raise ValueError("save_results needs an AteResult from evaluate_ate (with its evo result)")
    result = copy.deepcopy(ate.evo_result)
    old_ref, old_est = result.info["ref_name"], result.info["est_name"]
    result.info["ref_name"], result.info["est_name"] = ref_name, est_name
    trajectories = {ref_name: result.trajectories[old_ref], est_name: result.trajectories[old_est]}
    result.trajectories.clear()
    if SETTINGS.save_traj_in_zip:
        result.trajectories.update(trajectories)
    _atomic_write(Path(path), lambda fh: file_interface.save_res_file(fh, result))
