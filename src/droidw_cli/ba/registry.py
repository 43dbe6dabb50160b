"""Finding BA backends by name.

Backends register under the entry-point group ``droidw.backends`` (name →
``module:Class``, a :class:`~droidw_cli.ba.interface.BABackend` subclass).  The
CPU reference backend is always known, even when its entry point is missing
(``droidw_backend_cpu`` is imported directly).  Loading a backend class never
builds anything; :func:`get_backend` builds a compiled backend's kernels (CUDA,
native) only when that backend is chosen.  A backend class may name a
``fallback`` (the native one names ``cpu``): asked for by name where it cannot
run, the fallback runs instead and the choice records why.
"""

from __future__ import annotations

from dataclasses import dataclass
from importlib import import_module
from importlib.metadata import entry_points

from droidw_cli.ba.interface import BABackend
from droidw_cli.errors import UserError

ENTRY_POINT_GROUP = "droidw.backends"
#: always-available backends, used when their entry point is not installed
BUILTIN = {"cpu": "droidw_backend_cpu:CpuBackend"}
#: preference order of ``auto``: the GPU, then the fused C++ kernels (same results as ``cpu`` to float32
#: round-off, several times faster), then the vectorised torch reference
AUTO_ORDER = ("cuda", "native", "cpu")


@dataclass(frozen=True)
class BackendInfo:
    """One row of ``droidw backends``."""

    name: str
    available: bool
    reason: str


def _targets() -> dict[str, str]:
    """name → "module:Class" for every known backend (entry points win over built-ins)."""
    found = dict(BUILTIN)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        found[ep.name] = ep.value
    return found


def backend_names() -> list[str]:
    """Every registered backend name: the reference ``cpu`` first, then alphabetically."""
    return sorted(_targets(), key=lambda n: (n != "cpu", n))


def load_backend_class(name: str) -> type[BABackend]:
    """The backend class registered as ``name`` (ImportError if its package is broken)."""
    targets = _targets()
    if name not in targets:
        raise UserError(f"unknown BA backend '{name}' (known: auto, {', '.join(backend_names())})")
    module, _, attr = targets[name].partition(":")
    cls = getattr(import_module(module), attr)
    if not (isinstance(cls, type) and issubclass(cls, BABackend)):
        raise UserError(f"BA backend '{name}' ({targets[name]}) is not a BABackend subclass")
    return cls


def backend_info(name: str) -> BackendInfo:
    """Whether backend ``name`` can run here, and why (never builds kernels)."""
    try:
        cls = load_backend_class(name)
    except UserError as exc:
        return BackendInfo(name, False, str(exc))
    except Exception as exc:  # a broken plugin must not break the listing
        return BackendInfo(name, False, f"import failed: {type(exc).__name__}: {exc}")
    try:
        ok, reason = cls.availability()
    except Exception as exc:
        return BackendInfo(name, False, f"availability check failed: {type(exc).__name__}: {exc}")
    return BackendInfo(name, bool(ok), str(reason))


def list_backends() -> list[BackendInfo]:
    """One :class:`BackendInfo` per registered backend."""
    return [backend_info(n) for n in backend_names()]


def _instantiate(name: str) -> BABackend:
    backend = load_backend_class(name)()
    ensure = getattr(backend, "ensure_built", None)
    if callable(ensure):  # compiled backends build (or load their cache) now, not mid-run
        ensure()
    return backend


@dataclass(frozen=True)
class BackendChoice:
    """The backend a name resolved to: ``requested`` (e.g. ``auto``) and why the others were passed over."""

    backend: BABackend
    requested: str
    passed_over: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        return self.backend.name

    def describe(self) -> str:
        """One line, e.g. ``BA backend: cpu (auto; cuda: no CUDA device)`` or
        ``BA backend: cpu (instead of native: no C++ compiler …)``."""
        if self.requested != "auto":
            if self.passed_over:
                return f"BA backend: {self.name} (instead of {'; '.join(self.passed_over)})"
            return f"BA backend: {self.name}"
        return f"BA backend: {self.name} ({'; '.join(('auto',) + self.passed_over)})"


def resolve_backend(name: str = "auto") -> BackendChoice:
    """A ready backend and how it was chosen.

    ``auto`` tries :data:`AUTO_ORDER` (CUDA first): the first backend that is
    available here *and* starts (a CUDA backend builds or loads its kernels now)
    wins; each one passed over is listed with its reason.  Any other name must
    be available and start, else its class's ``fallback`` runs instead (the
    reason recorded in ``passed_over``), or without one :class:`UserError` names
    the CPU backend as the alternative.
    """
    if name == "auto":
        passed: list[str] = []
        for candidate in AUTO_ORDER:
            if candidate not in _targets():
                passed.append(f"{candidate}: not installed")
                continue
            info = backend_info(candidate)
            if not info.available:
                passed.append(f"{candidate}: {info.reason}")
                continue
            try:
                return BackendChoice(_instantiate(candidate), "auto", tuple(passed))
            except Exception as exc:  # e.g. the CUDA build failed: fall back to the next one
                passed.append(f"{candidate}: failed to start ({type(exc).__name__}: {exc})")
        raise UserError("no BA backend can run here (the cpu backend should always work: is droidw installed?); "
                        + "; ".join(passed))
    info = backend_info(name)
    if not info.available:
        return _fall_back(name, info.reason, UserError(f"the '{name}' BA backend cannot run here ({info.reason}); "
                                                       f"use --backend cpu (the CPU backend runs everywhere)"))
    try:
        return BackendChoice(_instantiate(name), name)
    except Exception as exc:
        err = UserError(f"the '{name}' BA backend failed to start ({exc}); "
                        f"use --backend cpu (the CPU backend runs everywhere)")
        return _fall_back(name, f"failed to start ({type(exc).__name__}: {exc})", err, exc)


def _fall_back(name: str, reason: str, error: UserError, cause: Exception | None = None) -> BackendChoice:
    """The choice of ``name``'s declared fallback backend, or ``error`` raised when it declares none."""
    try:
        fallback = getattr(load_backend_class(name), "fallback", None)
    except Exception:
        fallback = None
    if not fallback or fallback == name:
        raise error from cause
    return BackendChoice(_instantiate(fallback), name, (f"{name}: {reason}",))


def get_backend(name: str = "auto") -> BABackend:
    """A ready backend: ``auto`` (CUDA, else native, else CPU), ``cpu``, ``native``, ``cuda`` or a plugin name.

    Choosing a backend that cannot run here raises :class:`UserError` naming the
    CPU backend as the alternative (see :func:`resolve_backend`).
    """
    return resolve_backend(name).backend
