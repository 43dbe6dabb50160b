"""``summary.csv`` and ``summary.md`` of a batch: one row per sequence, then the mean.

Per sequence: status (``ok``, ``failed``, ``cancelled``), whether the result
was reused from an earlier run, ATE RMSE (metres in the CSV, centimetres in
the Markdown), matched poses, frames, keyframes, frames/s, seconds and the
error.  The mean row averages each number over the sequences that have it.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

from droidw_cli.io.trajectory import atomic_write_bytes

CSV_COLUMNS = ("name", "status", "reused", "ate_rmse_m", "matches", "frames", "keyframes", "fps", "seconds",
               "error", "input", "gt")
MEAN_COLUMNS = ("ate_rmse_m", "matches", "frames", "keyframes", "fps", "seconds")


def mean_row(records: list[dict]) -> dict:
    """The mean of each numeric column over the records that have it (None where none has)."""
    out: dict = {"name": "mean"}
    ok = sum(r.get("status") == "ok" for r in records)
    out["status"] = f"{ok}/{len(records)} ok"
    for col in MEAN_COLUMNS:
        vals = [float(r[col]) for r in records if r.get(col) is not None]
        out[col] = sum(vals) / len(vals) if vals else None
    return out


def _fmt(value, digits: int) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "yes" if value else ""
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return str(value)


def format_csv(records: list[dict]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    digits = {"ate_rmse_m": 6, "fps": 3, "seconds": 2}  # other floats (the mean's counts): 1
    for r in records + [mean_row(records)]:
        writer.writerow([_fmt(r.get(c), digits.get(c, 1)) for c in CSV_COLUMNS])
    return buf.getvalue()


def _md_cell(value) -> str:
    return str(value).replace("|", "\\|").replace("\n", " ")


def format_markdown(records: list[dict], title: str = "droidw batch") -> str:
    lines = [f"# {title}", "",
             "| sequence | status | ATE RMSE [cm] | matched | frames | keyframes | frames/s | seconds | error |",
             "|---|---|---|---|---|---|---|---|---|"]

    def row(r: dict, mean: bool) -> str:
        ate = None if r.get("ate_rmse_m") is None else 100.0 * float(r["ate_rmse_m"])
        status = str(r.get("status", "")) + (" (reused)" if r.get("reused") else "")
        nums = [_fmt(ate, 2), _fmt(r.get("matches"), 1), _fmt(r.get("frames"), 1), _fmt(r.get("keyframes"), 1),
                _fmt(r.get("fps"), 2), _fmt(r.get("seconds"), 1)]
        err = r.get("error") or ""
        err = err if len(err) <= 160 else err[:157] + "..."
        name = f"**{r['name']}**" if mean else r["name"]
        return "| " + " | ".join(_md_cell(c) for c in [name, status, *nums, err]) + " |"

    lines += [row(r, False) for r in records]
    lines.append(row(mean_row(records), True))
    return "\n".join(lines) + "\n"


def write_summary(out: Path, records: list[dict]) -> tuple[Path, Path]:
    """Write both files atomically; returns their paths."""
    csv_path, md_path = out / "summary.csv", out / "summary.md"
    atomic_write_bytes(csv_path, format_csv(records).encode())
    atomic_write_bytes(md_path, format_markdown(records).encode())
    return csv_path, md_path
