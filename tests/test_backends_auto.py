"""``--backend auto``: CUDA when it is available and starts, else the CPU; the choice is reported.

The registry is given a stand-in "cuda" backend (the CPU backend under another
name) that is available and either starts or fails to build, so both ways of
``auto`` run on a machine without a GPU.
"""

from __future__ import annotations

import json

import pytest
import torch

from droidw_cli.ba import registry
from droidw_cli.ba.registry import resolve_backend
from droidw_cli.cli import main
from droidw_cli.synth import SynthConfig, write_sequence
from droidw_backend_cpu import CpuBackend


class StandIn(CpuBackend):
    """A "cuda" backend that is available here; ``fail`` makes its build fail."""

    name = "cuda"
    fail = False

    @classmethod
    def availability(cls):
        return True, "stand-in"

    @classmethod
    def ensure_built(cls, verbose=False):
        if cls.fail:
            raise RuntimeError("nvcc exited with status 1")


@pytest.fixture
def stand_in(monkeypatch):
    real = registry.load_backend_class
    monkeypatch.setattr(registry, "_targets", lambda: {"cpu": registry.BUILTIN["cpu"], "cuda": "stand:in"})
    monkeypatch.setattr(registry, "load_backend_class", lambda name: StandIn if name == "cuda" else real(name))
    monkeypatch.setattr(StandIn, "fail", False)
    return StandIn


def test_auto_prefers_a_working_cuda_backend(stand_in):
    choice = resolve_backend("auto")
    assert choice.name == "cuda" and choice.requested == "auto" and choice.passed_over == ()
    assert choice.describe() == "BA backend: cuda (auto)"


def test_auto_falls_back_to_cpu_when_the_cuda_build_fails(stand_in, monkeypatch):
    monkeypatch.setattr(stand_in, "fail", True)
    choice = resolve_backend("auto")
    assert choice.name == "cpu"
    assert choice.passed_over == ("cuda: failed to start (RuntimeError: nvcc exited with status 1)",
                                  "native: not installed")  # the stand-in registry knows cpu and cuda only
    assert choice.describe().startswith("BA backend: cpu (auto; cuda: failed to start")


def test_auto_without_cuda_backend_installed(monkeypatch):
    monkeypatch.setattr(registry, "_targets", lambda: dict(registry.BUILTIN))
    choice = resolve_backend("auto")
    assert choice.name == "cpu" and choice.passed_over == ("cuda: not installed", "native: not installed")


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_auto_on_a_cpu_machine_says_why_not_cuda():
    choice = resolve_backend("auto")
    assert choice.name in ("native", "cpu")  # native where a compiler builds its kernels
    assert choice.passed_over[0] in ("cuda: no CUDA device", "cuda: not installed")
    assert (choice.name == "cpu") == (len(choice.passed_over) == 2)  # cpu only once native was passed over


def test_explicit_name_is_not_annotated():
    choice = resolve_backend("cpu")
    assert choice.name == "cpu" and choice.requested == "cpu" and choice.describe() == "BA backend: cpu"


@pytest.fixture(scope="module")
def tiny_seq(tmp_path_factory):
    cfg = SynthConfig.preset("static", width=320, height=240, frames=24, seed=2, camera_speed=2.5)
    return write_sequence(cfg, tmp_path_factory.mktemp("seq") / "static", progress=False)


@pytest.mark.parametrize("flag", [(), ("--backend", "cpu")])
def test_track_reports_the_backend(tiny_seq, tmp_path, capsys, flag, one_torch_thread):
    out = tmp_path / "run"
    args = ["track", str(tiny_seq), "--out", str(out), "--quiet", "--set", "io.target_area=76800",
            "--set", "uncertainty.enable=false", "--set", "backend.iters=2", "--set", "filler.iters=1", *flag]
    try:
        main(args)
    except SystemExit as exc:
        assert exc.code in (0, None)
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("droidw: BA backend")]
    info = json.loads((out / "run.json").read_text())
    expected = resolve_backend("auto").name if not flag else "cpu"
    assert info["backend"] == expected
    assert info["backend_choice"]["requested"] == ("auto" if not flag else "cpu")
    if flag:
        assert err == []  # an explicit choice needs no announcement
    else:
        assert err == [f"droidw: {resolve_backend('auto').describe()}"]
