"""Running a manifest: in order in this process, or as Ray tasks.

Ray is optional (``pip install 'droidw[ray]'``).  Without ``--address`` and
with more than one worker, a local Ray runtime is started with ``workers``
CPUs; with ``--address`` (``auto`` or ``ray://HOST:PORT``) the batch joins
that cluster.  Each sequence is one task with ``num_cpus = threads`` and
runs torch (and OpenCV) on that many threads, so that threads × tasks fit
the CPUs Ray hands out.  With one worker and no address the rows run in
order in this process, Ray or not.

A re-run skips sequences whose folder says ``ok`` unless ``force``.
Ctrl-C cancels what is running, removes the hidden partial folders, writes
the summary (unfinished rows ``cancelled``) and re-raises.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from droidw_cli.batch.manifest import Row
from droidw_cli.batch.summary import write_summary
from droidw_cli.batch.task import error_text, read_status, remove_partials, run_sequence
from droidw_cli.errors import UserError

INSTALL_HINT = "pip install 'droidw[ray]'"
OBJECT_STORE_BYTES = 128 * 1024 * 1024  # the tasks return small dicts; Ray's default takes 30 % of RAM


def ray_available() -> bool:
    try:
        import ray  # noqa: F401
    except ImportError:
        return False
    return True


def require_ray(why: str):
    """Import Ray, or a user error that says how to install it."""
    try:
        import ray
    except ImportError:
        raise UserError(f"{why} needs Ray, which is not installed: {INSTALL_HINT} "
                        "(or run the manifest in order with --workers 1)") from None
    return ray


@dataclass(frozen=True)
class BatchOptions:
    out: Path
    workers: int = 1
    address: str | None = None
    threads: int = 1
    force: bool = False
    backend: str = "auto"


def run_batch(rows: list[Row], opts: BatchOptions, progress: bool = False,
              report: Callable[[dict], None] = lambda rec: None) -> list[dict]:
    """Run (or skip) every row; returns the records in manifest order, summary written."""
    out = opts.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create the output folder {out}: {exc.strerror or exc}") from None
    remove_partials(out)  # left by a run that was killed
    records: dict[str, dict] = {}
    todo = []
    for row in rows:
        done = None if opts.force else read_status(out / row.name)
        if done is not None and done.get("status") == "ok":
            records[row.name] = {**done, "reused": True}
        else:
            todo.append(row)
    try:
        if todo and (opts.address is not None or opts.workers > 1):
            _run_ray(todo, opts, records, progress, report)
        else:
            _run_in_order(todo, opts, records, progress, report)
    except KeyboardInterrupt:
        remove_partials(out, {r.name for r in todo})
        _finish(rows, records, out)
        raise
    return _finish(rows, records, out)


def _finish(rows: list[Row], records: dict[str, dict], out: Path) -> list[dict]:
    """Write the summary; a row without a record (interrupted) reads its folder, else is ``cancelled``."""
    ordered = []
    for r in rows:
        rec = records.get(r.name) or read_status(out / r.name)  # a task may finish while Ctrl-C is handled
        ordered.append(rec or {"name": r.name, "input": r.input, "gt": r.gt, "status": "cancelled",
                               "error": "interrupted before it finished"})
    write_summary(out, ordered)
    return ordered


def _bar(total: int, progress: bool):
    from tqdm import tqdm

    return tqdm(total=total, desc="sequences", unit="seq", disable=not progress, leave=False)


def _run_in_order(todo: list[Row], opts: BatchOptions, records: dict, progress: bool, report) -> None:
    import torch

    before = torch.get_num_threads()
    try:
        with _bar(len(todo), progress) as bar:
            for row in todo:
                rec = run_sequence(row.as_dict(), str(opts.out), opts.threads, opts.backend)
                records[row.name] = rec
                report(rec)
                bar.update(1)
    finally:
        torch.set_num_threads(before)


def _run_ray(todo: list[Row], opts: BatchOptions, records: dict, progress: bool, report) -> None:
    why = "--address" if opts.address is not None else f"--workers {opts.workers}"
    ray = require_ray(why)
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no network calls from a batch
    started = False
    if not ray.is_initialized():
        if opts.address is None and opts.threads > opts.workers:
            raise UserError(f"--threads {opts.threads} is more than the {opts.workers} CPUs of --workers: "
                            "no task could start")
        try:
            if opts.address is not None:
                ray.init(address=opts.address, log_to_driver=False, logging_level="ERROR")
            else:
                ray.init(num_cpus=opts.workers, include_dashboard=False, log_to_driver=False,
                         logging_level="ERROR", object_store_memory=OBJECT_STORE_BYTES)
        except (ConnectionError, RuntimeError, ValueError) as exc:
            where = f"join the Ray cluster at {opts.address}" if opts.address else "start a local Ray runtime"
            raise UserError(f"cannot {where}: {error_text(exc)}") from None
        started = True
    remote = ray.remote(run_sequence)
    pending = {}
    try:
        for row in todo:
            task = remote.options(num_cpus=opts.threads, max_retries=0, name=f"droidw:{row.name}")
            pending[task.remote(row.as_dict(), str(opts.out), opts.threads, opts.backend)] = row
        with _bar(len(todo), progress) as bar:
            while pending:
                # a short timeout: Ctrl-C is only seen between calls, not inside Ray's blocking wait
                done, _ = ray.wait(list(pending), num_returns=1, timeout=0.5)
                for ref in done:
                    row = pending.pop(ref)
                    try:
                        rec = ray.get(ref)
                    except ray.exceptions.RayError as exc:  # the worker died (memory, a crash): record it
                        rec = {"name": row.name, "input": row.input, "gt": row.gt, "status": "failed",
                               "error": f"Ray task failed: {error_text(exc)}"}
                        remove_partials(opts.out, {row.name})
                    records[row.name] = rec
                    report(rec)
                    bar.update(1)
    except KeyboardInterrupt:
        _cancel(ray, list(pending))
        raise
    finally:
        if started:
            ray.shutdown()


def _cancel(ray, refs: list) -> None:
    """Cancel running tasks and wait (a little) until they are gone, so no worker still writes."""
    for ref in refs:
        try:
            ray.cancel(ref, force=True)
        except Exception:  # noqa: BLE001 - already finished or gone
            pass
    if refs:
        ray.wait(refs, num_returns=len(refs), timeout=30)
