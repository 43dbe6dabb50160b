"""``objects.json``: the dynamic objects of a run, one record per object id.

Schema (``droidw-objects/1``)::

    {
      "schema": "droidw-objects/1",
      "metric": bool,                      # centroids in metres (RGB-D) or in the run's arbitrary scale
      "objects": [
        {
          "id": int,
          "first_frame": int, "last_frame": int,           # input frame indices
          "first_timestamp": float, "last_timestamp": float, # seconds
          "keyframes": [
            {"keyframe": int, "frame": int, "timestamp": float,
             "centre": [x, y],              # inscribed-circle centre, input-image pixels
             "centroid": [x, y, z] | null,  # world frame (camera-to-world of traj.txt); null without depth
             "area": int}                   # pixels of the 1/8 BA grid
          ]
        }
      ]
    }

Objects are sorted by id and their keyframes by time.  The source is
``keyframes.npz``'s ``objects`` table (:data:`droidw_cli.dynamics.objects.TABLE_COLUMNS`).
"""

from __future__ import annotations

import json
import math

import numpy as np

SCHEMA = "droidw-objects/1"


def _num(v: float) -> float | None:
    return None if not math.isfinite(v) else float(v)


def objects_json(npz: dict, metric: bool) -> dict:
    """The ``objects.json`` document of a run's keyframe arrays (ValueError without an objects table)."""
    if "objects" not in npz:
        raise ValueError("the run has no dynamic-object record (tracked with dynamics.mode=none, or by an older droidw)")
    table = np.asarray(npz["objects"], dtype=np.float64).reshape(-1, 8)
    index = np.asarray(npz["index"], dtype=np.int64)
    stamps = np.asarray(npz["timestamps"], dtype=np.float64)
    objects = []
    for oid in np.unique(table[:, 1]).astype(np.int64):
        rows = table[table[:, 1] == oid]
        rows = rows[np.argsort(rows[:, 0], kind="stable")]
        kfs = rows[:, 0].astype(np.int64)
        objects.append({
            "id": int(oid),
            "first_frame": int(index[kfs[0]]), "last_frame": int(index[kfs[-1]]),
            "first_timestamp": float(stamps[kfs[0]]), "last_timestamp": float(stamps[kfs[-1]]),
            "keyframes": [
                {"keyframe": int(k), "frame": int(index[k]), "timestamp": float(stamps[k]),
                 "centre": [round(float(r[2]), 2), round(float(r[3]), 2)],
                 "centroid": None if not np.all(np.isfinite(r[4:7])) else [_num(v) for v in r[4:7]],
                 "area": int(r[7])}
                for k, r in zip(kfs, rows)
            ],
        })
    return {"schema": SCHEMA, "metric": bool(metric), "objects": objects}


def format_objects(doc: dict) -> str:
    return json.dumps(doc, indent=2) + "\n"
