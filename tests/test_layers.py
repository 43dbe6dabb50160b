"""The package's layers, read from the source: who may import whom, and how long a module may grow.

* ``commands/`` (the click entry points) is imported only by ``cli.py`` and by ``commands/`` itself: the
  library (batch, export, the benchmarks' track function) calls library functions.
* ``io/`` has no import cycle among its modules.
* ``dynamics/`` does not import ``slam/`` (the tracker uses the masks, not the other way round; the pose
  helpers both use live in ``geometry/``), and the layers below the tracker (runtime, geometry, io, ba,
  correspondence, features, eval) import neither ``slam/`` nor ``commands/``.
* Every ``droidw_cli`` name the tests and benchmarks import, also inside a function, exists.
* No module in ``src/`` is longer than 500 lines.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "droidw_cli"
MAX_LINES = 500


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(path: Path) -> set[str]:
    """Every ``droidw_cli`` module ``path`` imports, at the top or inside a function (relative imports resolved)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module_name(path).split(".")
    if path.name != "__init__.py":
        package = package[:-1]
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package[: len(package) - node.level + 1])
                mod = f"{base}.{node.module}" if node.module else base
            else:
                mod = node.module or ""
            found.add(mod)
            found.update(f"{mod}.{a.name}" for a in node.names)  # `from pkg import module`
    return {m for m in found if m == "droidw_cli" or m.startswith("droidw_cli.")}


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def in_package(name: str, package: str) -> bool:
    return name == package or name.startswith(package + ".")


def test_commands_are_imported_only_by_the_cli_and_by_commands():
    offenders = [f"{name} imports {m}" for name, path in modules().items()
                 if not in_package(name, "droidw_cli.commands") and name != "droidw_cli.cli"
                 for m in sorted(imports(path)) if in_package(m, "droidw_cli.commands")]
    assert offenders == []


def test_tests_and_benchmarks_take_only_click_commands_from_commands():
    """A test may import a command to invoke it; the library functions behind it live outside commands/."""
    import importlib

    import click

    root = SRC.parent
    offenders = []
    for path in sorted([*(root / "tests").glob("*.py"), *(root / "benchmarks").glob("*.py")]):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and in_package(node.module or "", "droidw_cli.commands"):
                module = importlib.import_module(node.module)
                offenders += [f"{path.name}: {node.module}.{a.name}" for a in node.names
                              if not isinstance(getattr(module, a.name, None), click.Command)]
            elif isinstance(node, ast.ImportFrom) and node.module == "droidw_cli":
                offenders += [f"{path.name}: droidw_cli.{a.name}" for a in node.names if a.name == "commands"]
    assert offenders == []


def test_every_droidw_import_in_tests_and_benchmarks_resolves():
    """A name a benchmark imports inside a function (run only in a full benchmark) still exists after a move."""
    import importlib

    root = SRC.parent
    missing = []
    for path in sorted([*(root / "tests").glob("*.py"), *(root / "benchmarks").glob("*.py")]):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and not node.level and in_package(node.module or "", "droidw_cli"):
                module = importlib.import_module(node.module)
                missing += [f"{path.name}: {node.module}.{a.name}" for a in node.names
                            if not hasattr(module, a.name) and importlib.util.find_spec(f"{node.module}.{a.name}") is None]
    assert missing == []


def test_io_has_no_import_cycle():
    mods = {n: p for n, p in modules().items() if in_package(n, "droidw_cli.io") and n != "droidw_cli.io"}
    graph = {n: sorted(m for m in imports(p) if m in mods and m != n) for n, p in mods.items()}
    state: dict[str, int] = {}  # 1: on the path, 2: done
    cycles = []

    def visit(n, path):
        state[n] = 1
        for m in graph[n]:
            if state.get(m) == 1:
                cycles.append(" -> ".join([*path[path.index(m):], m]))
            elif m not in state:
                visit(m, [*path, m])
        state[n] = 2

    for n in graph:
        if n not in state:
            visit(n, [n])
    assert cycles == []


def test_dynamics_imports_nothing_from_slam():
    offenders = [f"{name} imports {m}" for name, path in modules().items() if in_package(name, "droidw_cli.dynamics")
                 for m in sorted(imports(path)) if in_package(m, "droidw_cli.slam")]
    assert offenders == []


@pytest.mark.parametrize("package", ["droidw_cli.runtime", "droidw_cli.geometry", "droidw_cli.io", "droidw_cli.ba",
                                     "droidw_cli.correspondence", "droidw_cli.features", "droidw_cli.eval"])
def test_lower_layers_import_neither_slam_nor_commands(package):
    offenders = [f"{name} imports {m}" for name, path in modules().items() if in_package(name, package)
                 for m in sorted(imports(path))
                 if in_package(m, "droidw_cli.slam") or in_package(m, "droidw_cli.commands")]
    assert offenders == []


def test_the_layer_check_sees_imports():
    """The checks above would pass on a reader that found nothing: it finds the known imports."""
    assert "droidw_cli.runtime.timing" in imports(PACKAGE / "slam" / "tracker.py")
    assert "droidw_cli.io.frames" in imports(PACKAGE / "io" / "sources.py")
    assert "droidw_cli.commands" in imports(PACKAGE / "cli.py") or any(
        "droidw_cli.commands" in line for line in (PACKAGE / "cli.py").read_text().splitlines())


def test_no_module_over_500_lines():
    long = {str(p.relative_to(SRC)): n for p in sorted(SRC.rglob("*.py"))
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert long == {}
