"""The 3DGS PLY: every standard field, read back with plyfile, and droidw's own reader round trip."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.gaussians.model import Gaussians, SH_C0, dc_to_rgb
from droidw_cli.gaussians.ply import FLOAT_FIELDS, read_ply, write_ply

plyfile = pytest.importorskip("plyfile")


def gaussians(n=5) -> Gaussians:
    gen = torch.Generator().manual_seed(0)
    g = Gaussians(torch.randn(n, 3, generator=gen), torch.randn(n, 3, generator=gen) - 3,
                  torch.randn(n, 4, generator=gen), torch.randn(n, generator=gen), torch.randn(n, 3, generator=gen))
    return g


def test_static_ply_has_every_standard_field(tmp_path):
    g = gaussians()
    assert write_ply(tmp_path / "static.ply", g) == 5
    ply = plyfile.PlyData.read(str(tmp_path / "static.ply"))
    assert ply.text is False and ply.byte_order == "<"
    v = ply["vertex"]
    names = [p.name for p in v.properties]
    assert names == FLOAT_FIELDS
    assert all(p.val_dtype in ("f4", "float32") or np.dtype(p.val_dtype) == np.float32 for p in v.properties)
    xyz = np.stack([v["x"], v["y"], v["z"]], 1)
    np.testing.assert_allclose(xyz, g.means.numpy(), rtol=1e-6)
    np.testing.assert_allclose(np.stack([v[f"f_dc_{i}"] for i in range(3)], 1), g.dc.numpy(), rtol=1e-6)
    assert all(np.all(v[f"f_rest_{i}"] == 0) for i in range(45))
    assert all(np.all(v[n] == 0) for n in ("nx", "ny", "nz"))
    np.testing.assert_allclose(v["opacity"], g.opacity_logits.numpy(), rtol=1e-6)
    np.testing.assert_allclose(np.stack([v[f"scale_{i}"] for i in range(3)], 1), g.log_scales.numpy(), rtol=1e-6)
    q = np.stack([v[f"rot_{i}"] for i in range(4)], 1)
    np.testing.assert_allclose(q, (g.quats / g.quats.norm(dim=1, keepdim=True)).numpy(), rtol=1e-5, atol=1e-7)
    # the colour a viewer shows: 0.5 + C0 f_dc
    np.testing.assert_allclose(np.clip(0.5 + SH_C0 * np.stack([v[f"f_dc_{i}"] for i in range(3)], 1), 0, None),
                               dc_to_rgb(g.dc).numpy(), rtol=1e-6)


def test_dynamic_ply_adds_time_and_object_id_and_reads_back(tmp_path):
    g = gaussians(4)
    g.t = torch.tensor([0.5, 0.5, 1.25, 1.25], dtype=torch.float64)
    g.object_id = torch.tensor([0, 1, 0, 1])
    write_ply(tmp_path / "dynamic.ply", g, temporal=True)
    v = plyfile.PlyData.read(str(tmp_path / "dynamic.ply"))["vertex"]
    assert [p.name for p in v.properties][-2:] == ["t", "object_id"]
    np.testing.assert_array_equal(v["t"], g.t.numpy())
    np.testing.assert_array_equal(v["object_id"], g.object_id.numpy())
    back = read_ply(tmp_path / "dynamic.ply")
    for name in ("means", "log_scales", "opacity_logits", "dc"):
        torch.testing.assert_close(getattr(back, name), getattr(g, name))
    torch.testing.assert_close(back.t, g.t)
    assert back.object_id.tolist() == [0, 1, 0, 1]


def test_empty_ply_is_valid(tmp_path):
    write_ply(tmp_path / "e.ply", Gaussians.empty())
    assert plyfile.PlyData.read(str(tmp_path / "e.ply"))["vertex"].count == 0
