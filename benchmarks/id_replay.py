"""Object-id replay: the object tracker's parameters against id switches, without running SLAM again.

    python benchmarks/id_replay.py --capture [--presets walk wobble stopgo rotate] [--seeds 1 2] [--inputs rgbd mono]
    python benchmarks/id_replay.py [--set depth_tol=0.35 --set min_overlap=0.2 ...] [--only rotate-s1-rgbd ...]
    python benchmarks/id_replay.py --where [--only ...]

Object ids are given once the run is over (``droidw_cli.dynamics.objects.finish``), from the
keyframe masks, poses and depths of the run.  ``--capture`` tracks each cached preset (450 frames,
rendered into ``benchmarks/.cache`` as by ``dynamic_bench.py --modes``: RGB-D with the ``rgbd``
config and ``dynamics.mode`` both, monocular with the default config and epipolar masks), each in
its own process, and stores the inputs of that call, the keyframe indices and each walker's
ground-truth mask on the BA grid in ``benchmarks/.cache/ids/``.

Without ``--capture``: for every stored capture, the final masks
(:func:`~droidw_cli.dynamics.objects.final_pass`) and then the ids
(:func:`~droidw_cli.dynamics.objects.track_objects`) twice, with the
:class:`~droidw_cli.dynamics.tracker.DynamicObjectTracker` defaults and with the ``--set``
overrides of its fields.  Per capture and in total: the worst walker's id switches while in view
(in brackets over all keyframes where it has an id), the same as CLEAR MOT / MOTS count them
(``dynamic_bench.mots_id_switches``: one-to-one matching by mask IoU > 0.5; in brackets the share of
walkers in view matched), the share of walkers in view whose id another
walker in view has too, and the number of ids, as ``dynamic_bench.py --modes`` counts them.  Column
"same": the defaults gave the captured run's ids exactly (they do unless the object-id code changed since
the capture; capture again then).  Column "merged": the share of walkers in view (per keyframe) whose
component of the labelled mask (split at depth steps as the tracker splits it where it has depth) also holds
at least ``MERGED_SHARE`` of another walker in view: no association can give both their own id there; only
a split of the component can (the limit that the masks set, not the tracker's parameters).
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, print_table, run_case_subprocess, track_source  # noqa: E402
from dynamic_bench import (IN_VIEW, id_shared, id_switches, id_switches_any, instance_masks,  # noqa: E402
                           mots_id_switches, mots_matches, mots_switch_events)

STORE = Path(__file__).resolve().parent / ".cache" / "ids"
#: a walker's component "holds" another walker when it covers this share of the other's mask
MERGED_SHARE = 0.3
INPUTS = {"rgbd": ("rgbd", "both"), "mono": ("default", "epipolar")}


def capture_one(args: argparse.Namespace) -> None:
    """Track one cached preset and store what ``finish`` was given (internal: runs in a subprocess)."""
    import json

    import droidw_cli.slam.tracker as tracker_module
    from droidw_cli.config import load_config
    from droidw_cli.io.input import open_source
    from droidw_cli.synth import SynthConfig, build_scene

    config, mode = INPUTS[args.input]
    cfg = SynthConfig.preset(args.preset, seed=args.seed, apart=args.apart)
    source = open_source(cached_sequence(cfg, args.preset))
    source.strict_depth = args.input == "rgbd"
    seen = {}
    finish = tracker_module.finish

    def recording_finish(masks, poses_w2c, disps_obs, intrinsics, dyn_cfg, sensor_depth=False):
        seen["inputs"] = (masks, poses_w2c.clone(), disps_obs.clone(), intrinsics.clone(), dyn_cfg, sensor_depth)
        return finish(masks, poses_w2c, disps_obs, intrinsics, dyn_cfg, sensor_depth=sensor_depth)

    tracker_module.finish = recording_finish  # the run calls it by this module's name
    result, _ = track_source(source, source.intrinsics_hint, [f"dynamics.mode={mode}"], config=config)
    truth = instance_masks(cfg, build_scene(cfg), result.kf_index, load_config(config, []).io.target_area)
    STORE.mkdir(parents=True, exist_ok=True)
    path = STORE / f"{args.preset}{'-apart' if args.apart else ''}-s{args.seed}-{args.input}.pkl"
    tmp = path.with_suffix(".tmp")
    with open(tmp, "wb") as f:
        pickle.dump({"inputs": seen["inputs"], "ids": result.kf_object_ids, "truth": truth}, f)
    tmp.replace(path)
    print(json.dumps({"path": str(path), "keyframes": int(len(result.kf_index))}))


def replay(capture: dict, overrides: dict[str, object]) -> tuple[int, int, float, int, np.ndarray]:
    """Ids of a capture with the tracker's fields overridden: (switches, switches_any, shared, ids, id maps)."""
    import droidw_cli.dynamics.objects as objects

    masks, poses, disps, intrinsics, cfg, sensor_depth = capture["inputs"]
    if "final" not in capture:
        capture["final"] = objects.final_pass(masks, poses, disps, intrinsics, cfg, sensor_depth)
    default_tracker = objects.DynamicObjectTracker

    def tracker(**kwargs):
        made = default_tracker(**kwargs)
        for name, value in overrides.items():
            setattr(made, name, value)
        return made

    objects.DynamicObjectTracker = tracker
    try:
        rec = objects.track_objects(masks, poses, disps, intrinsics, cfg, [m.clone() for m in capture["final"]],
                                    sensor_depth)
    finally:
        objects.DynamicObjectTracker = default_tracker
    truth, ids = capture["truth"], rec.ids
    return (id_switches(truth, ids), id_switches_any(truth, ids), id_shared(truth, ids),
            int(len(np.unique(ids[ids >= 0]))), ids)


def merged_share(capture: dict, ids: np.ndarray) -> float:
    """Share of the (walker, keyframe) pairs in view whose component also holds another walker in view
    (column "merged" of the module docstring)."""
    from droidw_cli.dynamics.association import depth_components
    from droidw_cli.dynamics.tracker import DynamicObjectTracker

    _, _, disps, _, _, sensor_depth = capture["inputs"]
    truth = capture["truth"]
    visible = truth.reshape(len(truth), len(ids), -1).mean(2) >= IN_VIEW
    step = DynamicObjectTracker().depth_step
    merged = total = 0
    for k in range(len(ids)):
        d = disps[k].numpy().astype(np.float64)
        depth = np.where(d > 0, 1.0 / np.maximum(d, 1e-6), 0.0) if sensor_depth else None
        labels = depth_components(ids[k] >= 0, depth, step)
        for w in np.flatnonzero(visible[:, k]):
            hit = labels[truth[w, k] & (labels > 0)]
            if not hit.size:
                continue
            total += 1
            comp = labels == np.bincount(hit).argmax()
            merged += any((truth[o, k] & comp).sum() >= MERGED_SHARE * truth[o, k].sum()
                          for o in np.flatnonzero(visible[:, k]) if o != w)
    return merged / max(total, 1)


def parse_overrides(items: list[str]) -> dict[str, object]:
    """``field=value`` pairs of :class:`DynamicObjectTracker` fields, converted to the field's type."""
    from droidw_cli.dynamics.tracker import DynamicObjectTracker

    defaults = DynamicObjectTracker()
    known = [f.name for f in dataclasses.fields(DynamicObjectTracker)  # the parameters, not the tracking state
             if not f.name.startswith("_") and f.name != "frame" and isinstance(getattr(defaults, f.name), (int, float))]
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or name not in known:
            raise SystemExit(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {', '.join(known)}")
        out[name] = type(getattr(defaults, name))(value)
    return out


def capture_paths(only: list[str]) -> list[Path]:
    """The stored captures, those named in ``only`` if any; exits when there are none."""
    paths = [p for p in sorted(STORE.glob("*.pkl")) if not only or p.stem in set(only)]
    if not paths:
        raise SystemExit(f"no captures in {STORE}: run with --capture first")
    return paths


def replay_table(args: argparse.Namespace) -> None:
    overrides = parse_overrides(args.set)
    paths = capture_paths(args.only)
    rows, totals, merged, mots = [], np.zeros(4), [], []
    for path in paths:
        with open(path, "rb") as f:
            capture = pickle.load(f)
        base = replay(capture, {})
        new = replay(capture, overrides) if overrides else base
        same = bool(np.array_equal(base[4], capture["ids"]))
        merged.append(merged_share(capture, base[4]))
        mots.append(mots_id_switches(capture["truth"], base[4]))
        totals += [base[0], new[0], base[2], new[2]]
        rows.append([path.stem, f"{base[0]} ({base[1]})", f"{mots[-1][0]} ({100 * mots[-1][1]:.0f})",
                     f"{100 * base[2]:.0f}", f"{100 * merged[-1]:.0f}", base[3],
                     "yes" if same else "NO",
                     f"{new[0]} ({new[1]})", f"{100 * new[2]:.0f}", new[3]])
        print(" | ".join(str(c) for c in rows[-1]), file=sys.stderr, flush=True)
    rows.append(["total / mean", f"{totals[0]:.0f}", f"{sum(m[0] for m in mots)}", f"{100 * totals[2] / len(paths):.1f}",
                 f"{100 * np.mean(merged):.1f}", "", "",
                 f"{totals[1]:.0f}", f"{100 * totals[3] / len(paths):.1f}", ""])
    print(f"\nObject ids replayed, overrides: {overrides or 'none'}")
    print_table(["capture", "switches (any)", "MOTS switches (matched [%])", "shared [%]", "merged [%]", "ids", "same",
                 "with overrides: switches (any)", "shared [%]", "ids"], rows)


#: floor distances (m, between body axes) that ``--where`` counts switches in: through or touching each other,
#: close, apart
WHERE_BINS = (0.3, 0.6)


def capture_config(stem: str):
    """The generator's config of a capture named PRESET[-apart]-sN-INPUT (as :func:`capture_one` names it)."""
    from droidw_cli.synth import SynthConfig

    preset, _, rest = stem.rpartition("-s")
    return SynthConfig.preset(preset.removesuffix("-apart"), seed=int(rest.split("-")[0]),
                              apart=preset.endswith("-apart"))


def where_table(args: argparse.Namespace) -> None:
    """``--where``: per capture, each id switch (as MOTS counts them) and how close another walker came on the
    floor between the walker's two matches (the generator's walkers, body axis to body axis)."""
    from droidw_cli.synth import build_scene

    paths = capture_paths(args.only)
    rows, gaps = [], []
    for path in paths:
        with open(path, "rb") as f:
            capture = pickle.load(f)
        ids = replay(capture, {})[4]
        cfg = capture_config(path.stem)
        scene = build_scene(cfg)
        times = np.asarray(capture["inputs"][0].times, dtype=np.float64)
        frames = np.round((times - cfg.t0) * cfg.fps).astype(int)
        place = np.stack([w.walk.state(scene.walker_time(frames))[1][:, :2] for w in scene.walkers])  # (W, K, 2)
        near = []
        for w, j0, j1 in mots_switch_events(*mots_matches(capture["truth"], ids)):
            others = np.delete(place[:, j0:j1 + 1], w, axis=0)
            near.append(float(np.linalg.norm(others - place[w, j0:j1 + 1], axis=-1).min()) if len(others) else np.inf)
        gaps += near
        rows.append([path.stem, len(near), " ".join(f"{d:.2f}" for d in near) or "–"])
    g = np.asarray(gaps)
    lo, hi = WHERE_BINS
    print(f"\nId switches (MOTS) and the nearest other walker on the floor between the two matches [m]; of {len(g)}: "
          f"{(g < lo).sum()} under {lo} m, {((g >= lo) & (g < hi)).sum()} at {lo}-{hi} m, {(g >= hi).sum()} at {hi} m or more")
    print_table(["capture", "switches", "nearest other walker [m]"], rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--capture", action="store_true", help="track the presets and store the captures")
    ap.add_argument("--presets", nargs="+", default=["walk", "wobble", "stopgo", "rotate"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--inputs", nargs="+", choices=sorted(INPUTS), default=["rgbd", "mono"])
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a DynamicObjectTracker field for the replay")
    ap.add_argument("--only", nargs="+", default=[], metavar="NAME", help="captures to replay, e.g. rotate-s1-rgbd")
    ap.add_argument("--apart", action="store_true", help="capture scenes whose walkers keep apart (SynthConfig.apart), "
                    "stored as PRESET-apart-sN-INPUT")
    ap.add_argument("--where", action="store_true", help="per id switch (MOTS), how near another walker came "
                    "on the floor (the generator's ground truth)")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--preset", default="walk", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--input", default="rgbd", choices=sorted(INPUTS), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        capture_one(args)
    elif args.capture:
        for preset in args.presets:
            for seed in args.seeds:
                for kind in args.inputs:
                    r = run_case_subprocess("id_replay.py", ["--preset", preset, "--seed", str(seed),
                                                             "--input", kind] + (["--apart"] if args.apart else []))
                    print(f"captured {r['path']} ({r['keyframes']} keyframes)", file=sys.stderr, flush=True)
    elif args.where:
        where_table(args)
    else:
        replay_table(args)


if __name__ == "__main__":
    main()
