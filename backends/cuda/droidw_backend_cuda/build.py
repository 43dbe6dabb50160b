"""Lazy, cached build of the CUDA kernels with ``torch.utils.cpp_extension.load``.

Nothing here runs at import time.  :func:`load_kernels` compiles ``csrc/`` the
first time it is called in a process (ninja reuses the objects cached in
:func:`build_directory` across processes), and remembers a failure so that
``droidw backends`` can report "build failed: …" without retrying.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import ModuleType

from droidw_cli.ba.csrc import INCLUDE_DIR

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("droidw_ba.cpp", "linearize.cu", "similarity.cu")
EXTENSION_NAME = "droidw_ba_cuda"
#: compiler flags; no fast-math, so the kernels agree with the CPU backend to float32 rounding
CUDA_FLAGS = ("-O3", "--expt-relaxed-constexpr")
CXX_FLAGS = ("-O3",)

_kernels: ModuleType | None = None
_build_error: str | None = None


class KernelBuildError(RuntimeError):
    """The CUDA kernels could not be compiled or loaded (the message says why)."""


def build_directory() -> Path:
    """$TORCH_EXTENSIONS_DIR/droidw_ba_cuda, else ~/.cache/droidw/torch_extensions/droidw_ba_cuda."""
    root = os.environ.get("TORCH_EXTENSIONS_DIR")
    base = Path(root) if root else Path.home() / ".cache" / "droidw" / "torch_extensions"
    return base / EXTENSION_NAME


def build_error() -> str | None:
    """The first line of the last build failure in this process, if any."""
    return _build_error


def is_built() -> bool:
    """True once the kernels are loaded in this process."""
    return _kernels is not None


def load_kernels(verbose: bool = False) -> ModuleType:
    """The compiled kernel module (building it on first use); raises :class:`KernelBuildError`."""
    global _kernels, _build_error
    if _kernels is not None:
        return _kernels
    if _build_error is not None:
        raise KernelBuildError(_build_error)
    try:
        import torch
        from torch.utils import cpp_extension

        if not torch.cuda.is_available():
            raise KernelBuildError("no CUDA device")
        if cpp_extension.CUDA_HOME is None:
            raise KernelBuildError("no CUDA toolkit (nvcc) found; set CUDA_HOME")
        out = build_directory()
        out.mkdir(parents=True, exist_ok=True)
        _kernels = cpp_extension.load(
            name=EXTENSION_NAME,
            sources=[str(CSRC / s) for s in SOURCES],
            extra_include_paths=[str(CSRC), str(INCLUDE_DIR)],  # + the per-pixel maths shared with native
            extra_cflags=list(CXX_FLAGS),
            extra_cuda_cflags=list(CUDA_FLAGS),
            build_directory=str(out),
            verbose=verbose,
        )
    except KernelBuildError as exc:
        _build_error = str(exc)
        raise
    except Exception as exc:  # compiler errors, missing headers, link errors
        lines = [ln for ln in str(exc).strip().splitlines() if ln.strip()]
        _build_error = lines[0] if lines else type(exc).__name__
        raise KernelBuildError(_build_error) from exc
    return _kernels
