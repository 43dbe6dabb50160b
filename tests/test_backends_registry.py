"""Backend registry and ``droidw backends``."""

from __future__ import annotations

import json

import pytest
import torch
from click.testing import CliRunner

from droidw_cli.ba import registry
from droidw_cli.ba.registry import get_backend, list_backends
from droidw_cli.cli import cli
from droidw_cli.errors import UserError


def test_cpu_listed_and_available():
    rows = {r.name: r for r in list_backends()}
    assert rows["cpu"].available
    assert "cuda" in rows
    assert rows["cuda"].available == torch.cuda.is_available()


def test_get_backend_cpu_and_auto():
    assert get_backend("cpu").name == "cpu"
    expected = next(n for n in registry.AUTO_ORDER if n in registry.backend_names() and registry.backend_info(n).available)
    assert get_backend("auto").name == expected


def test_unknown_backend_is_a_user_error():
    with pytest.raises(UserError, match="unknown BA backend 'tpu'"):
        get_backend("tpu")


@pytest.mark.skipif(torch.cuda.is_available(), reason="needs a machine without CUDA")
def test_cuda_without_device_names_the_cpu_backend():
    with pytest.raises(UserError, match=r"no CUDA device.*--backend cpu"):
        get_backend("cuda")


def test_cpu_builtin_without_entry_point(monkeypatch):
    monkeypatch.setattr(registry, "entry_points", lambda group: [])
    assert registry.backend_names() == ["cpu"]
    assert get_backend("auto").name == "cpu"


def test_importing_cuda_package_is_safe_and_does_not_build():
    import droidw_backend_cuda
    from droidw_backend_cuda import build

    ok, reason = droidw_backend_cuda.CudaBackend.availability()
    assert isinstance(reason, str) and reason
    if not torch.cuda.is_available():
        assert not ok and reason == "no CUDA device"
        assert not build.is_built()


def test_droidw_backends_command():
    result = CliRunner().invoke(cli, ["backends"])
    assert result.exit_code == 0, result.output
    lines = result.output.strip().splitlines()
    assert lines[0].startswith("cpu: available (")
    cuda = [ln for ln in lines if ln.startswith("cuda: ")]
    assert len(cuda) == 1
    if not torch.cuda.is_available():
        assert cuda[0] == "cuda: unavailable (no CUDA device)"
    result = CliRunner().invoke(cli, ["backends", "--json"])
    rows = [json.loads(ln) for ln in result.output.strip().splitlines()]
    assert {"name": "cpu", "available": True}.items() <= rows[0].items()
