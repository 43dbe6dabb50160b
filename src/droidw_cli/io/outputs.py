"""Checks on output paths, made before the work that would fill them.

A long run whose output folder turns out to be a file, or to lie under a
path that cannot be created, should fail at once with one line, not after
minutes of tracking with a traceback.  The checks only look: nothing is
created until the results are written (atomically, by the writers), except
for an empty probe folder made and removed at once in the nearest existing
ancestor.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from droidw_cli.errors import UserError


class OutputError(UserError):
    """An output path cannot be written."""


def _writable_ancestor(folder: Path) -> None:
    """Raise unless ``folder`` exists as a writable folder or could be created as one."""
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise OutputError(f"cannot create {folder}: {probe} is not a folder")
    try:  # a real probe: permissions, read-only mounts and pseudo file systems all show
        os.rmdir(tempfile.mkdtemp(prefix=".droidw-probe-", dir=probe))
    except OSError as exc:
        raise OutputError(f"cannot write into {probe}: {exc.strerror or exc}") from None


def check_output_folder(path: str | Path) -> Path:
    """``path`` as an absolute path, after checking that it is, or can become, a writable folder."""
    p = Path(path).expanduser().absolute()
    if p.exists() and not p.is_dir():
        raise OutputError(f"{path} exists and is not a folder")
    _writable_ancestor(p)
    return p


def check_output_file(path: str | Path) -> Path:
    """``path`` as an absolute path, after checking that a file can be written there."""
    p = Path(path).expanduser().absolute()
    if p.is_dir():
        raise OutputError(f"{path} is a folder, not a file name")
    _writable_ancestor(p.parent)
    return p


def describe_os_error(exc: OSError) -> str:
    """One line for an OSError that escaped to the command line (the user's path, not a temporary name)."""
    reason = exc.strerror or str(exc)
    if not exc.filename:
        return reason
    p = Path(exc.filename)
    if p.name.startswith(".") and p.name.endswith(".tmp"):  # the writers' temporary files (atomic writes)
        return f"cannot write into {p.parent}: {reason}"
    return f"{exc.filename}: {reason}"
