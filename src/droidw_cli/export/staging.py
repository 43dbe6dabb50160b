"""An export folder written all-or-nothing (``droidw export nerfstudio`` / ``colmap``).

The folder is filled under a hidden temporary name beside ``--out`` and moved
into place by one rename only when every file is complete, so a failure (a
missing input frame, a full disk, Ctrl-C) leaves nothing behind.  ``--out``
must not exist yet or be an empty folder: an export never mixes its files with
older ones.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

from droidw_cli.io.outputs import OutputError, check_output_folder


def check_export_folder(path: str | Path) -> Path:
    """``path`` as an absolute path, after checking that it is missing or an empty, writable folder."""
    p = check_output_folder(path)
    if p.is_dir() and any(p.iterdir()):
        raise OutputError(f"{path} exists and is not empty; choose another --out or remove it")
    return p


@contextmanager
def staged_folder(path: str | Path) -> Iterator[Path]:
    """Yield a temporary folder beside ``path``; on success it becomes ``path`` (an empty ``path`` is replaced).

    On any exception the temporary folder is removed and ``path`` is left as it was.
    """
    out = check_export_folder(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes 0700; give the usual permissions
        os.replace(tmp, out)  # POSIX rename: replaces an empty folder, fails on a non-empty one
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
