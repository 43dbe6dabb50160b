"""The standard 3DGS PLY (binary little-endian), written by droidw and read back.

One vertex per Gaussian with the float properties of the original 3DGS code's files, which SuperSplat and
most viewers read: ``x y z``, ``nx ny nz`` (zeros), ``f_dc_0..2`` (the SH degree-0 coefficients),
``f_rest_0..44`` (zeros: no higher SH bands; some viewers reject files without them), ``opacity`` (the logit),
``scale_0..2`` (log standard deviations), ``rot_0..3`` (the quaternion w, x, y, z).  Temporal Gaussians add
``double t`` (their keyframe's timestamp, seconds) and ``int object_id``.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import torch

from droidw_cli.gaussians.model import Gaussians

FLOAT_FIELDS = (["x", "y", "z", "nx", "ny", "nz"] + [f"f_dc_{i}" for i in range(3)] +
                [f"f_rest_{i}" for i in range(45)] + ["opacity"] + [f"scale_{i}" for i in range(3)] +
                [f"rot_{i}" for i in range(4)])


def vertex_array(g: Gaussians, temporal: bool = False) -> np.ndarray:
    """The PLY's vertex records as a structured array."""
    dtype = [(n, "<f4") for n in FLOAT_FIELDS] + ([("t", "<f8"), ("object_id", "<i4")] if temporal else [])
    out = np.zeros(len(g), dtype=dtype)
    cols = {"x": g.means[:, 0], "y": g.means[:, 1], "z": g.means[:, 2], "opacity": g.opacity_logits}
    cols.update({f"f_dc_{i}": g.dc[:, i] for i in range(3)})
    cols.update({f"scale_{i}": g.log_scales[:, i] for i in range(3)})
    q = g.quats / g.quats.norm(dim=1, keepdim=True).clamp_min(1e-12)
    cols.update({f"rot_{i}": q[:, i] for i in range(4)})
    for name, col in cols.items():
        out[name] = col.detach().cpu().numpy()
    if temporal:
        out["t"] = g.t.cpu().numpy() if g.t is not None else 0.0
        out["object_id"] = g.object_id.cpu().numpy() if g.object_id is not None else -1
    return out


def write_ply(path: str | Path, g: Gaussians, temporal: bool = False) -> int:
    """Write ``g`` atomically (a temporary file beside ``path``, then renamed); returns the vertex count."""
    path = Path(path)
    data = vertex_array(g, temporal)
    kind = {"<f4": "float", "<f8": "double", "<i4": "int"}
    header = ["ply", "format binary_little_endian 1.0", "comment droidw Gaussian map (3DGS layout, SH degree 0)",
              f"element vertex {len(data)}"]
    header += [f"property {kind[data.dtype[n].str]} {n}" for n in data.dtype.names] + ["end_header"]
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(("\n".join(header) + "\n").encode("ascii"))
            fh.write(data.tobytes())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return len(data)


def read_ply(path: str | Path) -> Gaussians:
    """Read a binary little-endian 3DGS PLY (droidw's, or any with the standard fields) into Gaussians."""
    raw = Path(path).read_bytes()
    end = raw.index(b"end_header\n") + len(b"end_header\n")
    lines = raw[:end].decode("ascii").splitlines()
    if "format binary_little_endian 1.0" not in lines:
        raise ValueError(f"{path}: not a binary little-endian PLY")
    kinds = {"float": "<f4", "double": "<f8", "int": "<i4", "uchar": "u1", "uint": "<u4"}
    props = [(ln.split()[2], kinds[ln.split()[1]]) for ln in lines if ln.startswith("property ")]
    n = next(int(ln.split()[2]) for ln in lines if ln.startswith("element vertex"))
    data = np.frombuffer(raw, dtype=props, count=n, offset=end)
    col = (lambda *names: torch.as_tensor(np.stack([data[x] for x in names], axis=1).astype(np.float32)))
    g = Gaussians(col("x", "y", "z"), col("scale_0", "scale_1", "scale_2"), col("rot_0", "rot_1", "rot_2", "rot_3"),
                  torch.as_tensor(data["opacity"].astype(np.float32)), col("f_dc_0", "f_dc_1", "f_dc_2"))
    if "t" in data.dtype.names:
        g.t = torch.as_tensor(data["t"].astype(np.float64))
        g.object_id = torch.as_tensor(data["object_id"].astype(np.int64))
    return g
