"""One sequence of a batch: ``track``, then ``eval`` where a ground truth is given.

:func:`run_sequence` is what a Ray task (or the in-order loop) runs.  It
writes everything into a hidden ``.NAME.partial-*`` folder beside the final
one and renames it to ``NAME`` only at the end, so a sequence folder is
either complete or absent; an interrupted sequence leaves only the hidden
folder, which the batch removes.  Any error is caught and recorded: the
folder then holds ``status.json`` (status ``failed``, the error) and
``error.txt`` (the traceback).

Sequence folder: ``traj.txt``, ``keyframes.npz``, ``calib.txt``,
``run.json`` (as ``droidw track``), ``eval.json`` and ``ate.zip`` (evo's
result format) when there is a ground truth, and ``status.json``.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import time
import traceback
import uuid
from pathlib import Path

from droidw_cli.errors import UserError

STATUS_FILE = "status.json"
PARTIAL_MARK = ".partial-"
OLD_MARK = ".old-"


def partial_dir(out: Path, name: str) -> Path:
    return out / f".{name}{PARTIAL_MARK}{uuid.uuid4().hex[:8]}"


def read_status(folder: Path) -> dict | None:
    """The ``status.json`` of a finished sequence folder, or None."""
    try:
        return json.loads((folder / STATUS_FILE).read_text())
    except (OSError, ValueError):
        return None


def error_text(exc: BaseException) -> str:
    """One line: the message of a user error, else the exception type and message."""
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if isinstance(exc, UserError):
        return msg or type(exc).__name__
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def run_sequence(row: dict, out_dir: str, threads: int = 1, backend: str = "auto") -> dict:
    """Track (and evaluate) one manifest row into ``out_dir/NAME``; returns its status record."""
    import cv2
    import torch

    torch.set_num_threads(max(1, int(threads)))
    cv2.setNumThreads(max(1, int(threads)))
    out = Path(out_dir)
    name = row["name"]
    tmp = partial_dir(out, name)
    record = {"name": name, "input": row["input"], "gt": row.get("gt"), "status": "failed", "error": None,
              "ate_rmse_m": None, "matches": None, "align": None,
              "frames": None, "keyframes": None, "fps": None, "seconds": None, "warnings": 0,
              "threads": int(threads), "host": platform.node()}
    start = time.perf_counter()
    try:
        tmp.mkdir(parents=True)
        try:
            _track_and_eval(row, tmp, backend, record, int(threads))
            record["status"] = "ok"
        except Exception as exc:  # noqa: BLE001 - a failing sequence is recorded, the batch goes on
            record["error"] = error_text(exc)
            (tmp / "error.txt").write_text(traceback.format_exc())
        record["seconds"] = round(time.perf_counter() - start, 3)
        (tmp / STATUS_FILE).write_text(json.dumps(record, indent=2) + "\n")
        _move_into_place(tmp, out / name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return record


def _track_and_eval(row: dict, folder: Path, backend: str, record: dict, threads: int) -> None:
    from droidw_cli.track import run_track

    inp = Path(row["input"])
    if not inp.exists():
        raise UserError(f"input not found: {inp}")
    result, _ = run_track(inp, folder, row.get("calib"), backend, row.get("config") or "default",
                          (f"threads={max(1, threads)}", *(row.get("overrides") or ())), progress=False,
                          echo=lambda *a, **k: None, depth=bool(row.get("depth")),
                          depth_scale=float(row["depth_scale"]))
    record.update(frames=int(len(result.timestamps)), keyframes=int(len(result.kf_index)),
                  fps=round(float(result.fps), 3), warnings=len(result.warnings))
    if row.get("gt"):
        record["align"] = row.get("align") or ("se3" if result.metric else "sim3")
        _evaluate(row, folder, record)


def _evaluate(row: dict, folder: Path, record: dict) -> None:
    from droidw_cli.eval import evaluate_ate, inputs
    from droidw_cli.eval.report import EvalInfo, save_results, to_json_dict
    from droidw_cli.io.trajectory import read_trajectory

    gt = inputs.load(row["gt"], "auto", None, role="gt")
    if not gt.has_timestamps:
        raise UserError(f"{gt.path}: a KITTI ground truth has no timestamps; give a TUM or EuRoC file")
    est = read_trajectory(folder / "traj.txt")
    max_diff = 0.02
    ate = evaluate_ate(gt.traj, est, record["align"], max_diff)
    info = EvalInfo(str(gt.path), str(folder.parent / row["name"] / "traj.txt"), len(gt.traj), len(est), max_diff)
    (folder / "eval.json").write_text(json.dumps(to_json_dict(info, ate), indent=2) + "\n")
    save_results(folder / "ate.zip", ate, str(gt.path), row["name"])
    record.update(ate_rmse_m=float(ate.rmse), matches=int(ate.matches))


def _move_into_place(tmp: Path, final: Path) -> None:
    """Rename ``tmp`` to ``final``; an existing ``final`` is swapped out first, then removed."""
    if final.exists():
        old = final.parent / f".{final.name}{OLD_MARK}{uuid.uuid4().hex[:8]}"
        os.replace(final, old)
        os.replace(tmp, final)
        shutil.rmtree(old, ignore_errors=True)
    else:
        os.replace(tmp, final)


def remove_partials(out: Path, names: set[str] | None = None) -> int:
    """Remove hidden ``.NAME.partial-*`` / ``.NAME.old-*`` folders (of ``names``, or all); returns the count."""
    if not out.is_dir():
        return 0
    n = 0
    for p in out.iterdir():
        if not (p.is_dir() and p.name.startswith(".")):
            continue
        for mark in (PARTIAL_MARK, OLD_MARK):
            if mark in p.name and (names is None or p.name[1:].split(mark)[0] in names):
                shutil.rmtree(p, ignore_errors=True)
                n += 1
                break
    return n
