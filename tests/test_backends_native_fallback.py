"""The native backend where it cannot be built: the run falls back to ``cpu`` and says so once.

No compiler is simulated by patching :mod:`droidw_backend_native.build` (no
cached module, no ``c++``), a failing build by a ``load_kernels`` that raises;
neither compiles anything.  The shared header is checked to compile with the
host compiler alone (no torch, no CUDA), as the CUDA kernels include it.
"""

from __future__ import annotations

import json
import subprocess
from types import SimpleNamespace

import pytest

from droidw_cli.ba.csrc import HEADER, INCLUDE_DIR
from droidw_cli.ba.registry import resolve_backend
from droidw_cli.cli import main
from droidw_cli.synth import SynthConfig, write_sequence
from droidw_backend_native import NativeBackend, build


@pytest.fixture
def no_compiler(monkeypatch, tmp_path):
    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))  # nothing cached there
    monkeypatch.setenv("CXX", str(tmp_path / "no-such-compiler"))
    monkeypatch.setattr(build, "_kernels", None)
    monkeypatch.setattr(build, "_build_error", None)


def test_availability_says_there_is_no_compiler(no_compiler):
    ok, reason = NativeBackend.availability()
    assert not ok and reason.startswith("no C++ compiler") and "set CXX" in reason


def test_asking_for_native_falls_back_to_cpu(no_compiler):
    choice = resolve_backend("native")
    assert choice.name == "cpu" and choice.requested == "native"
    assert len(choice.passed_over) == 1 and choice.passed_over[0].startswith("native: no C++ compiler")
    assert choice.describe().startswith("BA backend: cpu (instead of native: no C++ compiler")


def test_auto_passes_over_native_without_a_compiler(no_compiler):
    choice = resolve_backend("auto")
    assert choice.name in ("cpu", "cuda")
    if choice.name == "cpu":
        assert any(p.startswith("native: no C++ compiler") for p in choice.passed_over)


def test_a_failed_build_falls_back_too(monkeypatch):
    def fail(verbose=False):
        raise build.KernelBuildError("error: 'foo' was not declared in this scope")

    monkeypatch.setattr(build, "load_kernels", fail)
    choice = resolve_backend("native")
    assert choice.name == "cpu"
    assert choice.passed_over == ("native: failed to start (KernelBuildError: error: 'foo' was not declared "
                                  "in this scope)",)


def test_compiling_is_announced_once(monkeypatch, tmp_path, capsys):
    """The first build says so on stderr (the compiler itself is stubbed out here)."""
    from torch.utils import cpp_extension

    monkeypatch.setenv("TORCH_EXTENSIONS_DIR", str(tmp_path / "ext"))
    monkeypatch.setattr(build, "_kernels", None)
    monkeypatch.setattr(build, "_build_error", None)
    monkeypatch.setattr(build, "missing_tool", lambda: None)
    calls = []
    monkeypatch.setattr(cpp_extension, "load", lambda **kw: calls.append(kw) or SimpleNamespace(name=kw["name"]))
    first = build.load_kernels()
    assert build.load_kernels() is first and len(calls) == 1
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("droidw: compiling the native BA kernels (once per machine")
    assert str(build.build_directory()) in err[0]
    assert calls[0]["build_directory"] == str(build.build_directory())


@pytest.fixture(scope="module")
def tiny_seq(tmp_path_factory):
    cfg = SynthConfig.preset("static", width=320, height=240, frames=24, seed=2, camera_speed=2.5)
    return write_sequence(cfg, tmp_path_factory.mktemp("seq") / "static", progress=False)


def test_track_without_a_compiler_runs_on_cpu_and_records_it(no_compiler, tiny_seq, tmp_path, capsys,
                                                             one_torch_thread):
    out = tmp_path / "run"
    args = ["track", str(tiny_seq), "--out", str(out), "--quiet", "--backend", "native", "--set",
            "io.target_area=76800", "--set", "uncertainty.enable=false", "--set", "backend.iters=2",
            "--set", "filler.iters=1"]
    try:
        main(args)
    except SystemExit as exc:
        assert exc.code in (0, None)
    lines = [ln for ln in capsys.readouterr().err.splitlines() if "BA backend" in ln]
    assert len(lines) == 1 and lines[0].startswith("droidw: BA backend: cpu (instead of native: no C++ compiler")
    info = json.loads((out / "run.json").read_text())
    assert info["backend"] == "cpu"
    assert info["backend_choice"]["requested"] == "native"
    assert info["backend_choice"]["passed_over"][0].startswith("native: no C++ compiler")


def test_shared_header_compiles_without_torch_or_cuda(tmp_path):
    """droidw_pixel.h is plain C++ under the host compiler (the CUDA kernels include the same file)."""
    cxx = build.compiler()
    if cxx is None:
        pytest.skip("no C++ compiler here")
    src = tmp_path / "use.cpp"
    src.write_text(f'#include "{HEADER}"\n'
                   "float use(const float* g) {\n"
                   "  droidw::Pinhole k{50.f, 50.f, 32.f, 24.f};\n"
                   "  droidw::Projected o = droidw::project_pixel(g, k, 3, 4, 0.5f, 0.05f);\n"
                   "  float ju[8], jv[8], a, b;\n"
                   "  droidw::jacobian_rows<8>(o, g, k, droidw::kFocalXY, 0.5f, ju, jv);\n"
                   "  droidw::depth_derivative(o, g, k, a, b);\n"
                   "  droidw::Bilinear c = droidw::bilinear_corners(o.px, o.py, 48, 64);\n"
                   "  return ju[7] + jv[6] + a + b + c.w[0] + droidw::weight_factor(0.9f, droidw::kUncertaintyClamp)\n"
                   "         + droidw::similarity_term(droidw::similarity_score(0.7f, 0.5f, 0.2f, 1.f), o.valid, 0.1f,\n"
                   "                                   1.f, 1.f);\n"
                   "}\n")
    done = subprocess.run([cxx, "-std=c++17", "-Wall", "-Werror", "-fsyntax-only", f"-I{INCLUDE_DIR}", str(src)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
