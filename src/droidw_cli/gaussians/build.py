"""``droidw map`` as a library call: read the run, fit the static map and the object Gaussians, score the
held-out frames, and write ``MAP/`` all at once.

Outputs (docs/formats.md): ``static.ply`` and ``dynamic.ply`` (:mod:`.ply`), ``views/`` (:mod:`.heldout`) and
``map.json`` (the settings, steps, seconds, Gaussian counts and scores).  Everything is written into a hidden
temporary folder beside ``MAP`` and moved into place only when complete, so a failure leaves nothing partial.

The time budget (``--minutes``) is shared out: the static map may run until 70 % of it has passed, the
objects until 90 %; scoring and writing take the rest.  A budget too small for the static map to take a
single step is an error.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import torch

from droidw_cli.errors import UserError
from droidw_cli.gaussians.dynamic_map import fit_objects
from droidw_cli.gaussians.heldout import evaluate
from droidw_cli.gaussians.inputs import load_inputs
from droidw_cli.gaussians.params import MapParams
from droidw_cli.gaussians.ply import write_ply
from droidw_cli.gaussians.raster import resolve_rasteriser
from droidw_cli.gaussians.static_map import Deadline, StaticMapper

STATIC_SHARE, OBJECT_SHARE = 0.7, 0.9
MIN_SECONDS = 6.0  # below this no run folder can even be read
OUTPUTS = ("static.ply", "dynamic.ply", "views", "map.json")


def run_map(run_dir: Path, out_dir: Path, params: MapParams, input_path: Path | None = None,
            progress: bool = False, echo=None) -> dict:
    """Fit and write the map of ``run_dir`` into ``out_dir``; returns the content of ``map.json``."""
    from droidw_cli.io.outputs import check_output_folder

    t0 = time.perf_counter()
    budget = params.minutes * 60.0
    if budget < MIN_SECONDS:
        raise UserError(f"--minutes {params.minutes:g} is too short to map anything (at least "
                        f"{MIN_SECONDS / 60:.2f} minutes; the default is {MapParams().minutes:g})")
    out = check_output_folder(out_dir)
    torch.manual_seed(params.seed)
    rasteriser, how = resolve_rasteriser(params.rasteriser)
    inputs = load_inputs(Path(run_dir), params, input_path)
    if echo is not None:  # after the checks of the run, so that an error stays one line
        echo(f"droidw: rasteriser: {how}")
    t_load = time.perf_counter() - t0
    mapper = StaticMapper(inputs, params, rasteriser, Deadline(t0, STATIC_SHARE * budget), progress)
    static, static_info = mapper.run()
    if static_info["steps"] == 0:
        raise UserError(f"--minutes {params.minutes:g} is too short: reading the run took {t_load:.0f} s and left "
                        f"no time for a single mapping step; give it a few minutes")
    t_static = time.perf_counter() - t0 - t_load
    dynamic, dyn_info = fit_objects(inputs, static, params, rasteriser, Deadline(t0, OBJECT_SHARE * budget),
                                    progress and inputs.has_masks, mapper.scene_depth) if inputs.has_masks else (
        None, {"steps": 0, "ended": "no masks", "keyframes": 0, "keyframes_with_objects": 0, "objects": []})
    if dynamic is None:
        from droidw_cli.gaussians.model import Gaussians

        dynamic = Gaussians.empty()
        dynamic.t, dynamic.object_id = torch.zeros(0, dtype=torch.float64), torch.zeros(0, dtype=torch.int64)
    t_dynamic = time.perf_counter() - t0 - t_load - t_static
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".droidw-map-", dir=out.parent))
    try:
        (tmp / "views").mkdir()
        scores = evaluate(inputs, static, dynamic, rasteriser, tmp / "views")
        write_ply(tmp / "static.ply", static)
        write_ply(tmp / "dynamic.ply", dynamic, temporal=True)
        doc = {"schema": "droidw-map/1", "run": str(run_dir), "input": inputs.input, "rasteriser": how,
               "settings": {**params.to_dict(), "size": list(inputs.size)}, "metric": inputs.metric,
               "masks": inputs.has_masks, "intrinsics": list(inputs.intrinsics),
               "keyframes": len(inputs.keyframes), "heldout_frames": len(inputs.heldout),
               "gaussians": {"static": len(static), "dynamic": len(dynamic)},
               "static": {k: v for k, v in static_info.items()}, "objects": dyn_info,
               "seconds": {"read": round(t_load, 2), "static": round(t_static, 2), "objects": round(t_dynamic, 2),
                           "total": round(time.perf_counter() - t0, 2)},
               "heldout": scores}
        (tmp / "map.json").write_text(json.dumps(doc, indent=2) + "\n")
        _move_into(tmp, out)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return doc


def _move_into(tmp: Path, out: Path) -> None:
    """Put the finished outputs in place: the whole folder when ``out`` does not exist, else file by file."""
    if not out.exists():
        os.replace(tmp, out)
        return
    for name in OUTPUTS:
        target = out / name
        if target.is_dir():
            shutil.rmtree(target)
        os.replace(tmp / name, target)
