"""Lazy, cached build of the native CPU kernels with ``torch.utils.cpp_extension``.

Nothing here runs at import time.  :func:`load_kernels` builds ``csrc/`` (and
the shared header of :mod:`droidw_cli.ba.csrc`) the first time it is needed on
a machine, saying so once on stderr, into a directory named after a hash of
the sources, the flags, torch, Python and the CPU (the code is built for the
host CPU, ``-march=native``); later processes import the cached module
directly, without a compiler or ninja.  A failure is remembered, so that
``droidw backends`` can report "build failed: …" without retrying, and the
registry falls back to the ``cpu`` backend.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import platform
import shutil
import sys
from pathlib import Path
from types import ModuleType

from droidw_cli.ba.csrc import HEADER, INCLUDE_DIR

CSRC = Path(__file__).resolve().parent / "csrc"
SOURCES = ("bindings.cpp", "linearize.cpp", "ba_step.cpp", "similarity.cpp", "reproject.cpp")
HEADERS = ("native_ba.h",)
#: -fopenmp: at::parallel_for runs on torch's OpenMP pool (the same libgomp); no fast-math, so the kernels
#: agree with the torch backend to float32 rounding (fused multiply-adds only)
CXX_FLAGS = ("-O3", "-march=native", "-ffp-contract=fast", "-fno-math-errno", "-fopenmp")
LD_FLAGS = ("-fopenmp",)
BASE_NAME = "droidw_ba_native"

_kernels: ModuleType | None = None
_build_error: str | None = None


class KernelBuildError(RuntimeError):
    """The native kernels could not be compiled or loaded (the message says why)."""


def _cpu_signature() -> str:
    """What the -march=native code depends on: the CPU's model and feature flags."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
        keep = [ln for ln in lines if ln.startswith(("model name", "flags"))][:2]
        return "\n".join(keep)
    except OSError:
        return platform.processor()


def extension_name() -> str:
    """``droidw_ba_native_<hash>``: a new name (and directory) whenever sources, flags, torch or CPU change."""
    import torch

    h = hashlib.sha256()
    for path in [CSRC / s for s in SOURCES + HEADERS] + [INCLUDE_DIR / HEADER]:
        h.update(path.name.encode())
        h.update(path.read_bytes())
    h.update(" ".join(CXX_FLAGS + LD_FLAGS).encode())
    h.update(f"{torch.__version__} {sys.version_info[:2]} {platform.machine()}".encode())
    h.update(_cpu_signature().encode())
    return f"{BASE_NAME}_{h.hexdigest()[:12]}"


def build_directory() -> Path:
    """$TORCH_EXTENSIONS_DIR/<name>, else ~/.cache/droidw/torch_extensions/<name>."""
    root = os.environ.get("TORCH_EXTENSIONS_DIR")
    base = Path(root) if root else Path.home() / ".cache" / "droidw" / "torch_extensions"
    return base / extension_name()


def cached_library() -> Path | None:
    """The built module of these sources on this machine, if there is one."""
    so = build_directory() / f"{extension_name()}.so"
    return so if so.is_file() else None


def compiler() -> str | None:
    """The C++ compiler torch would use ($CXX, else c++), or None when there is none."""
    return shutil.which(os.environ.get("CXX", "c++"))


def missing_tool() -> str | None:
    """Why the kernels cannot be built here (no compiler, no ninja), or None."""
    if compiler() is None:
        return f"no C++ compiler ({os.environ.get('CXX', 'c++')}) to build the kernels; install g++ or set CXX"
    if _ninja() is None:
        return "no ninja to build the kernels; pip install ninja"
    return None


def _ninja() -> str | None:
    """The ninja binary: on PATH, beside this Python, or from the ``ninja`` package."""
    found = shutil.which("ninja") or shutil.which("ninja", path=str(Path(sys.executable).parent))
    if found:
        return found
    try:
        import ninja  # the PyPI package ships the binary

        return shutil.which("ninja", path=ninja.BIN_DIR)
    except (ImportError, AttributeError):
        return None


def build_error() -> str | None:
    """The first line of the last build failure in this process, if any."""
    return _build_error


def is_built() -> bool:
    """True once the kernels are loaded in this process."""
    return _kernels is not None


def _import(name: str, path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _compile(name: str, out: Path, verbose: bool) -> ModuleType:
    import torch  # noqa: F401  (the extension links against the loaded torch)
    from torch.utils import cpp_extension

    ninja = _ninja()
    path = os.environ.get("PATH", "")
    if ninja and shutil.which("ninja") is None:  # torch runs `ninja` from PATH
        os.environ["PATH"] = os.pathsep.join([str(Path(ninja).parent), path]) if path else str(Path(ninja).parent)
    print(f"droidw: compiling the native BA kernels (once per machine, about a minute; cached in {out})",
          file=sys.stderr, flush=True)
    try:
        return cpp_extension.load(
            name=name,
            sources=[str(CSRC / s) for s in SOURCES],
            extra_include_paths=[str(CSRC), str(INCLUDE_DIR)],
            extra_cflags=list(CXX_FLAGS),
            extra_ldflags=list(LD_FLAGS),
            build_directory=str(out),
            verbose=verbose,
        )
    finally:
        os.environ["PATH"] = path


def load_kernels(verbose: bool = False) -> ModuleType:
    """The compiled kernel module (building it on first use); raises :class:`KernelBuildError`."""
    global _kernels, _build_error
    if _kernels is not None:
        return _kernels
    if _build_error is not None:
        raise KernelBuildError(_build_error)
    try:
        name = extension_name()
        cached = cached_library()
        if cached is not None:
            _kernels = _import(name, cached)
            return _kernels
        missing = missing_tool()
        if missing is not None:
            raise KernelBuildError(missing)
        out = build_directory()
        out.mkdir(parents=True, exist_ok=True)
        _kernels = _compile(name, out, verbose)
    except KernelBuildError as exc:
        _build_error = str(exc)
        raise
    except Exception as exc:  # compiler errors, missing headers, link errors
        lines = [ln for ln in str(exc).strip().splitlines() if ln.strip()]
        _build_error = lines[0] if lines else type(exc).__name__
        raise KernelBuildError(_build_error) from exc
    return _kernels
