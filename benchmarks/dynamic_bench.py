"""Dynamic-scene benchmark: what the uncertainty buys, and RGB-D against monocular per mask mode.

    python benchmarks/dynamic_bench.py [--frames 300] [--size 640x480] [--seeds 1 2 3] [--set KEY=VALUE ...]
    python benchmarks/dynamic_bench.py --modes [--presets walk wobble stopgo rotate] [--mono-modes ...]
                                       [--rgbd-modes ...] [--frames 0]
    python benchmarks/dynamic_bench.py --auroc [--presets follow follow-pan walk forward] [--seeds 1 2]

Default table: one row per sequence (3 dynamic seeds and a static control):
ATE with and without uncertainty and their ratio, the uncertainty AUROC
against the ground-truth dynamic masks over all keyframes, the share of
ground-truth dynamic pixels in the static point cloud, and frames/s for both runs.

``--modes``: one row per realistic 640×480 preset (450 frames; rendered into
``benchmarks/.cache`` like track_bench) and run: monocular (``default``
config, Sim(3) ATE) and RGB-D (``rgbd`` config, SE(3) ATE), each with every
``dynamics.mode`` asked for.  Per run: ATE, the IoU of the keyframes' dynamic
masks (``keyframes.npz`` ``dynamic``) against the ground truth on the BA
grid (pooled over the keyframes where a walker covers ≥ 1 cell) with its precision and recall, object-id
switches of the worst walker while it stays in view (:func:`id_switches`; in
brackets the older count over all keyframes where it has an id,
:func:`id_switches_any`), the number of object ids, the share of walkers in view whose id
another walker in view has too (:func:`id_shared`), the id switches as CLEAR MOT / MOTS count them
(:func:`mots_id_switches`, with the share of walkers in view matched to an id), the share of ground-truth
dynamic pixels in the static cloud, and frames/s.

``--auroc``: one row per preset and seed (cached like ``--modes``, each preset's own length; default
config plus ``--set``, known calibration): ATE (cm and % of the path), the AUROC of the keyframes'
uncertainty u for the ground-truth dynamic mask on the BA grid per keyframe with movers, averaged
(the same restricted to mover 0 — a follow shot's subject — against the static cells, and to the other
movers against the static cells), the pooled AUROC over all keyframes as the first table has it, the
keyframes (with movers) and frames/s:

    python benchmarks/dynamic_bench.py --auroc --presets follow walk forward --seeds 1
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _bench_common import cached_sequence, print_table, run_case_subprocess, track_source  # noqa: E402


def keyframe_masks(cfg, scene, kf_index: np.ndarray, target_area: int) -> np.ndarray:
    """Ground-truth dynamic masks of the keyframes on the BA grid."""
    import cv2

    from droidw_cli.geometry.camera import BA_SCALE
    from droidw_cli.io.prepare import FramePreparer

    prep = FramePreparer((cfg.height, cfg.width), None, target_area)
    h, w = prep.size[0] // BA_SCALE, prep.size[1] // BA_SCALE
    out = np.zeros((len(kf_index), h, w), dtype=bool)
    for n, k in enumerate(kf_index):
        m = scene.frame(int(k)).mask.astype(np.uint8) * 255
        work = prep.image(np.repeat(m[..., None], 3, axis=2))[..., 0].astype(np.float32) / 255.0
        out[n] = cv2.resize(work, (w, h), interpolation=cv2.INTER_AREA) >= 0.5
    return out


def one(args: argparse.Namespace) -> None:
    from droidw_cli.config import load_config
    from droidw_cli.eval import evaluate_ate
    from droidw_cli.eval.dynamic import auroc
    from droidw_cli.export.pointcloud import CloudParams, build_cloud
    from droidw_cli.export.run_files import keyframe_arrays
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import SynthConfig, build_scene
    from droidw_cli.synth.source import SynthSource

    w, h = (int(v) for v in args.size.split("x"))
    cfg = SynthConfig.preset(args.preset, width=w, height=h, frames=args.frames, seed=args.seed)
    scene = build_scene(cfg)
    gt = Trajectory(np.array([cfg.timestamp(k) for k in range(cfg.frames)]),
                    np.asarray(scene.pose(np.arange(cfg.frames)), dtype=np.float64))
    source = SynthSource(cfg)
    overrides = list(args.set) + ([] if args.uncertainty else ["uncertainty.enable=false"])
    result, seconds = track_source(source, source.intrinsics_hint, overrides)
    out = {"ate_cm": evaluate_ate(gt, Trajectory(result.timestamps, result.poses_c2w)).rmse * 100,
           "fps": len(result.timestamps) / seconds, "keyframes": int(len(result.kf_index))}
    if args.uncertainty and result.kf_uncertainty is not None:
        target_area = load_config("default", list(args.set)).io.target_area
        masks = keyframe_masks(cfg, scene, result.kf_index, target_area)
        out["auroc"] = auroc(result.kf_uncertainty, masks) if masks.any() else float("nan")
        cloud = build_cloud(keyframe_arrays(result), CloudParams())
        dyn = masks.reshape(-1)
        out["static_points"] = int(cloud.static.sum())
        out["static_dynamic_share"] = float((cloud.static & dyn).sum() / max(1, cloud.static.sum()))
    print(json.dumps(out))


def instance_masks(cfg, scene, kf_index: np.ndarray, target_area: int) -> np.ndarray:
    """(walkers, K, h, w) ground-truth mask of each walker (where it is the nearest surface) on the BA grid."""
    import cv2

    from droidw_cli.geometry.camera import BA_SCALE
    from droidw_cli.io.prepare import FramePreparer

    prep = FramePreparer((cfg.height, cfg.width), None, target_area)
    h, w = prep.size[0] // BA_SCALE, prep.size[1] // BA_SCALE
    out = np.zeros((len(scene.walkers), len(kf_index), h, w), dtype=bool)
    for n, k in enumerate(kf_index):
        pose = scene.pose(int(k))
        full = scene.caster.cast(scene.boxes(int(k)), pose).depth
        t = float(scene.walker_time(int(k)))
        for i, walker in enumerate(scene.walkers):
            hits = scene.caster.cast(scene.static_boxes + walker.boxes(t), pose)
            m = (hits.dynamic & (hits.depth <= full + 1e-6)).astype(np.uint8) * 255
            work = prep.image(np.repeat(m[..., None], 3, axis=2))[..., 0].astype(np.float32) / 255.0
            out[i, n] = cv2.resize(work, (w, h), interpolation=cv2.INTER_AREA) >= 0.5
    return out


def id_switches_any(instances: np.ndarray, ids: np.ndarray) -> int:
    """The old metric: the most id changes of any walker, per keyframe where it has an id, the id overlapping it most.

    Counts changes across keyframes where the walker left the image or was hidden, too."""
    worst = 0
    for inst in instances:
        seq = []
        for m, lab in zip(inst, ids):
            hit = lab[m & (lab >= 0)]
            if hit.size:
                seq.append(int(np.bincount(hit).argmax()))
        worst = max(worst, sum(a != b for a, b in zip(seq, seq[1:])))
    return worst


#: a walker is "in view" in a keyframe when it covers at least this share of the BA grid's cells
IN_VIEW = 0.005


def id_switches(instances: np.ndarray, ids: np.ndarray, in_view: float = IN_VIEW) -> int:
    """Id switches while in view (issue 11: "at most one id switch per object per sequence while it stays in view").

    Per walker, its keyframes split into *visits*: maximal runs of consecutive keyframes in which
    its ground-truth mask (where it is the nearest surface) covers at least ``in_view`` of the grid
    (0.5 %: 15 cells at 48 × 64).  A walker covering fewer cells (leaving at the border, hidden behind
    another) is out of view: it may come back with a new id.  Within a visit, the id of a keyframe is
    the one overlapping the walker most (keyframes where no id overlaps it are skipped); a switch is a
    change between consecutive ids.  Returns the most switches of any walker, summed over its visits.
    """
    worst = 0
    for inst in instances:
        visible = inst.reshape(len(inst), -1).mean(1) >= in_view
        total, seq = 0, []
        for m, lab, vis in zip(inst, ids, visible):
            if not vis:
                total += sum(a != b for a, b in zip(seq, seq[1:]))
                seq = []
                continue
            hit = lab[m & (lab >= 0)]
            if hit.size:
                seq.append(int(np.bincount(hit).argmax()))
        total += sum(a != b for a, b in zip(seq, seq[1:]))
        worst = max(worst, total)
    return worst


def id_shared(instances: np.ndarray, ids: np.ndarray, in_view: float = IN_VIEW) -> float:
    """Share of the (walker, keyframe) pairs in view with an id (as in :func:`id_switches`) whose id is
    also that of another walker in view: few id switches mean little when one id covers a pile of walkers."""
    k = ids.shape[0]
    visible = instances.reshape(len(instances), k, -1).mean(2) >= in_view
    best = np.full(visible.shape, -1)
    for w, inst in enumerate(instances):
        for j in np.flatnonzero(visible[w]):
            hit = ids[j][inst[j] & (ids[j] >= 0)]
            if hit.size:
                best[w, j] = np.bincount(hit).argmax()
    have = best >= 0
    same = (best[:, None, :] == best[None, :, :]) & have[:, None, :] & have[None, :, :]
    same &= ~np.eye(len(instances), dtype=bool)[:, :, None]
    return float(same.any(1)[have].sum() / max(1, have.sum()))


#: MOTS (Voigtlaender et al. 2019) matches a ground-truth object and a track when their masks overlap with IoU > 0.5
MOTS_IOU = 0.5


def mots_matches(instances: np.ndarray, ids: np.ndarray, iou: float = MOTS_IOU,
                 in_view: float = IN_VIEW) -> tuple[np.ndarray, np.ndarray]:
    """Per walker and keyframe its matched id (−1: none) and whether it is in view (both (walkers, K)).

    Per keyframe each walker in view is matched to at most one id and each id to at most one walker:
    the assignment of largest total mask IoU, of which the pairs with IoU > ``iou`` are kept (CLEAR MOT's
    matching, on masks as in MOTS)."""
    from scipy.optimize import linear_sum_assignment

    n, k = instances.shape[:2]
    visible = instances.reshape(n, k, -1).mean(2) >= in_view
    matched = np.full((n, k), -1)
    for j in range(k):
        tracks = np.unique(ids[j][ids[j] >= 0])
        if not len(tracks):
            continue
        overlap = np.zeros((n, len(tracks)))
        for c, t in enumerate(tracks):
            mask = ids[j] == t
            for w in np.flatnonzero(visible[:, j]):
                overlap[w, c] = (mask & instances[w, j]).sum() / max(1, (mask | instances[w, j]).sum())
        rows, cols = linear_sum_assignment(-overlap)
        keep = overlap[rows, cols] > iou
        matched[rows[keep], j] = tracks[cols[keep]]
    return matched, visible


def mots_switch_events(matched: np.ndarray, visible: np.ndarray) -> list[tuple[int, int, int]]:
    """The switches of :func:`mots_matches`' output as (walker, keyframe of the last match, keyframe of the new id):
    a matched id that differs from the walker's previous matched id in the same visit (keyframes in view)."""
    events = []
    for w in range(len(matched)):
        last = None
        for j in range(matched.shape[1]):
            if not visible[w, j]:
                last = None  # a new visit
            elif matched[w, j] >= 0:
                if last is not None and matched[w, j] != matched[w, last]:
                    events.append((w, last, j))
                last = j
    return events


def mots_id_switches(instances: np.ndarray, ids: np.ndarray, iou: float = MOTS_IOU,
                     in_view: float = IN_VIEW) -> tuple[int, float]:
    """Id switches as CLEAR MOT counts them (IDSW), on masks as MOTS does, while in view (as :func:`id_switches`).

    Matching by :func:`mots_matches`, switches by :func:`mots_switch_events`.  Unlike :func:`id_switches`, a
    walker that one id covers together with another walker (a pile) is unmatched there, not given the pile's id.
    Returns the worst walker's switches and the share of (walker, keyframe) pairs in view that are matched.
    """
    matched, visible = mots_matches(instances, ids, iou, in_view)
    per_walker = np.bincount([w for w, _, _ in mots_switch_events(matched, visible)], minlength=len(matched))
    worst = int(per_walker.max()) if len(per_walker) else 0
    return worst, float((matched >= 0).sum() / max(1, visible.sum()))


def one_mode(args: argparse.Namespace) -> None:
    """One --modes case: a cached preset tracked with one config and dynamics.mode; prints a JSON line."""
    from droidw_cli.config import load_config
    from droidw_cli.eval import evaluate_ate
    from droidw_cli.export.pointcloud import CloudParams, build_cloud
    from droidw_cli.export.run_files import keyframe_arrays
    from droidw_cli.io.input import open_source
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import SynthConfig, build_scene

    cfg = SynthConfig.preset(args.preset, seed=args.seed, apart=args.apart,
                             **({"frames": args.frames} if args.frames else {}))
    source = open_source(cached_sequence(cfg, args.preset))
    overrides = [f"dynamics.mode={args.mode}", *args.set]
    if args.config == "rgbd":
        source.strict_depth = True
    result, seconds = track_source(source, source.intrinsics_hint, overrides, config=args.config)
    scene = build_scene(cfg)
    gt = Trajectory(np.array([cfg.timestamp(k) for k in range(cfg.frames)]),
                    np.asarray(scene.pose(np.arange(cfg.frames)), dtype=np.float64))
    est = Trajectory(result.timestamps, result.poses_c2w)
    out = {"sim3_cm": evaluate_ate(gt, est).rmse * 100, "se3_cm": evaluate_ate(gt, est, "se3").rmse * 100,
           "fps": len(result.timestamps) / seconds, "keyframes": int(len(result.kf_index))}
    area = load_config(args.config, overrides).io.target_area
    inst = instance_masks(cfg, scene, result.kf_index, area)
    truth = inst.any(0)
    if result.kf_dynamic is not None:
        pred = result.kf_dynamic
        seen = truth.reshape(len(truth), -1).any(1)
        out["iou"] = float((pred & truth)[seen].sum() / max(1, (pred | truth)[seen].sum()))
        out["precision"] = float((pred & truth)[seen].sum() / max(1, pred[seen].sum()))
        out["recall"] = float((pred & truth)[seen].sum() / max(1, truth[seen].sum()))
        out["id_switches"] = id_switches(inst, result.kf_object_ids)
        out["id_switches_any"] = id_switches_any(inst, result.kf_object_ids)
        out["id_shared"] = id_shared(inst, result.kf_object_ids)
        out["mots_switches"], out["mots_matched"] = mots_id_switches(inst, result.kf_object_ids)
        out["objects"] = int(len(np.unique(result.objects[:, 1]))) if len(result.objects) else 0
    cloud = build_cloud(keyframe_arrays(result), CloudParams())
    out["static_dynamic_share"] = float((cloud.static & truth.reshape(-1)).sum() / max(1, cloud.static.sum()))
    print(json.dumps(out))


def mean_auroc(u: np.ndarray, positive: np.ndarray, negative: np.ndarray) -> tuple[float, int]:
    """The AUROC of u for ``positive`` cells against ``negative`` ones per keyframe, averaged over the keyframes
    that have both; and their number."""
    from droidw_cli.eval.dynamic import auroc

    scores = [auroc(uk[p | n], p[p | n]) for uk, p, n in zip(u, positive, negative) if p.any() and n.any()]
    return (float(np.mean(scores)) if scores else float("nan")), len(scores)


def one_auroc(args: argparse.Namespace) -> None:
    """One --auroc case: a cached preset tracked with the default config; prints a JSON line."""
    from droidw_cli.config import load_config
    from droidw_cli.eval import evaluate_ate
    from droidw_cli.eval.dynamic import auroc
    from droidw_cli.io.calibration import Calibration
    from droidw_cli.io.input import open_source
    from droidw_cli.io.trajectory import Trajectory
    from droidw_cli.synth import SynthConfig, build_scene

    cfg = SynthConfig.preset(args.preset, seed=args.seed, **({"frames": args.frames} if args.frames else {}))
    source = open_source(cached_sequence(cfg, args.preset))
    result, seconds = track_source(source, Calibration(*(float(v) for v in cfg.intrinsics)), list(args.set))
    scene = build_scene(cfg)
    poses = np.asarray(scene.pose(np.arange(cfg.frames)), dtype=np.float64)
    gt = Trajectory(np.array([cfg.timestamp(k) for k in range(cfg.frames)]), poses)
    path = float(np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum())
    ate = evaluate_ate(gt, Trajectory(result.timestamps, result.poses_c2w)).rmse
    out = {"ate_cm": ate * 100, "ate_path": 100 * ate / max(path, 1e-9), "keyframes": int(len(result.kf_index)),
           "fps": len(result.timestamps) / seconds}
    u = result.kf_uncertainty
    if u is not None:
        inst = instance_masks(cfg, scene, result.kf_index, load_config("default", list(args.set)).io.target_area)
        truth = inst.any(0)
        static = ~truth
        out["auroc"], out["kf_movers"] = mean_auroc(u, truth, static)
        out["auroc_subject"], out["kf_subject"] = mean_auroc(u, inst[0], static)
        out["auroc_others"], out["kf_others"] = mean_auroc(u, inst[1:].any(0), static)
        out["auroc_pooled"] = auroc(u, truth) if truth.any() else float("nan")
        if args.save_u:
            Path(args.save_u).parent.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(args.save_u, u=u, truth=truth, subject=inst[0], kf_index=result.kf_index)
    print(json.dumps(out))


def auroc_table(args: argparse.Namespace) -> None:
    rows = []
    for preset in args.presets:
        for seed in args.seeds:
            case = ["--one-auroc", "--preset", preset, "--seed", str(seed), "--frames", str(args.frames),
                    *(x for s in args.set for x in ("--set", s))]
            case += ["--save-u", str(Path(args.save_u) / f"{preset}-seed{seed}.npz")] if args.save_u else []
            r = run_case_subprocess("dynamic_bench.py", case)
            nan = float("nan")
            rows.append([preset, seed, f"{r['ate_cm']:.2f}", f"{r['ate_path']:.3f}", f"{r.get('auroc', nan):.3f}",
                         f"{r.get('auroc_subject', nan):.3f} ({r.get('kf_subject', 0)})",
                         f"{r.get('auroc_others', nan):.3f} ({r.get('kf_others', 0)})",
                         f"{r.get('auroc_pooled', nan):.3f}", f"{r['keyframes']} ({r.get('kf_movers', 0)})",
                         f"{r['fps']:.2f}"])
            print(" | ".join(str(c) for c in rows[-1]), file=sys.stderr, flush=True)
    print("\nUncertainty against the dynamic mask (default config, known calibration, per keyframe with movers)")
    print_table(["preset", "seed", "ATE [cm]", "ATE [% path]", "AUROC u, dynamic (kf mean)",
                 "AUROC mover 0 / subject (kf)", "AUROC other movers (kf)", "AUROC pooled", "keyframes (with movers)",
                 "frames/s"], rows)


def modes_table(args: argparse.Namespace) -> None:
    common = ["--frames", str(args.frames)] + [x for s in args.set for x in ("--set", s)]
    common += ["--apart"] if args.apart else []
    rows = []
    for preset in args.presets:
        runs = [("default", m) for m in args.mono_modes] + [("rgbd", m) for m in args.rgbd_modes]
        for config, mode in runs:
            r = run_case_subprocess("dynamic_bench.py", ["--one-mode", "--preset", preset, "--seed", str(args.seeds[0]),
                                                         "--config", config, "--mode", mode, *common])
            ate = r["se3_cm"] if config == "rgbd" else r["sim3_cm"]
            rows.append([preset, "RGB-D" if config == "rgbd" else "mono", mode,
                         f"{ate:.2f} ({'SE3' if config == 'rgbd' else 'Sim3'})", f"{r.get('iou', float('nan')):.2f}",
                         f"{r.get('precision', float('nan')):.2f} / {r.get('recall', float('nan')):.2f}",
                         f"{r['id_switches']} ({r['id_switches_any']})" if "id_switches" in r else "–",
                         f"{r['mots_switches']} ({100 * r['mots_matched']:.0f})" if "mots_switches" in r else "–",
                         r.get("objects", "–"), f"{100 * r['id_shared']:.0f}" if "id_shared" in r else "–",
                         f"{100 * r['static_dynamic_share']:.2f}", f"{r['fps']:.2f}"])
            print(" | ".join(str(c) for c in rows[-1]), file=sys.stderr, flush=True)
    print(f"\nMask modes, monocular and RGB-D, 640x480 presets (seed {args.seeds[0]})")
    print_table(["sequence", "input", "dynamics.mode", "ATE [cm]", "mask IoU", "mask precision / recall",
                 "id switches in view (any)", "MOTS id switches (matched [%])",
                 "objects", "ids shared [%]", "dynamic in static PLY [%]", "frames/s"], rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--size", default="640x480")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    ap.add_argument("--modes", action="store_true", help="the RGB-D / monocular mask-mode table")
    ap.add_argument("--presets", nargs="+", default=["walk", "wobble", "stopgo", "rotate"],
                    help="--modes / --auroc: any synth preset (e.g. forward, follow, follow-pan)")
    ap.add_argument("--mono-modes", nargs="*", default=["epipolar", "consistency", "both"])
    ap.add_argument("--rgbd-modes", nargs="*", default=["epipolar", "consistency", "both"])
    ap.add_argument("--apart", action="store_true", help="with --modes: walkers keep apart (SynthConfig.apart)")
    ap.add_argument("--auroc", action="store_true", help="the AUROC-of-u table per preset and seed (--presets)")
    ap.add_argument("--save-u", default="", metavar="DIR",
                    help="with --auroc: save each run's keyframe u and ground-truth masks as DIR/PRESET-seedN.npz")
    ap.add_argument("--one-auroc", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--one-mode", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--config", default="default", help=argparse.SUPPRESS)
    ap.add_argument("--mode", default="epipolar", help=argparse.SUPPRESS)
    ap.add_argument("--preset", default="dynamic", help=argparse.SUPPRESS)
    ap.add_argument("--seed", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--uncertainty", type=int, default=1, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one_auroc:  # (the table passes --frames; 0 = the preset's own length)
        one_auroc(args)
        return
    if args.one_mode:  # run_case_subprocess also passes --one
        one_mode(args)
        return
    if args.one:
        one(args)
        return
    if args.modes or args.auroc:
        if args.frames == 300:  # the default of the first table; the presets keep their own length
            args.frames = 0
        (auroc_table if args.auroc else modes_table)(args)
        return
    common = ["--size", args.size, "--frames", str(args.frames)] + [x for s in args.set for x in ("--set", s)]
    cases = [("dynamic", s) for s in args.seeds] + [("static", args.seeds[0])]
    rows, ratios, ate_on, ate_off = [], [], [], []
    for preset, seed in cases:
        on = run_case_subprocess("dynamic_bench.py", ["--preset", preset, "--seed", str(seed), *common])
        off = run_case_subprocess("dynamic_bench.py", ["--preset", preset, "--seed", str(seed), "--uncertainty", "0",
                                                       *common])
        ratio = off["ate_cm"] / max(on["ate_cm"], 1e-9)
        if preset == "dynamic":
            ratios.append(ratio)
            ate_on.append(on["ate_cm"])
            ate_off.append(off["ate_cm"])
        rows.append([f"{preset} seed {seed}", f"{on['ate_cm']:.2f}", f"{off['ate_cm']:.2f}", f"{ratio:.2f}",
                     f"{on.get('auroc', float('nan')):.3f}", f"{100 * on.get('static_dynamic_share', 0.0):.2f}",
                     f"{on['fps']:.2f}", f"{off['fps']:.2f}"])
    print(f"\nDynamic scenes, {args.size}, {args.frames} frames")
    print_table(["sequence", "ATE on [cm]", "ATE off [cm]", "off/on", "AUROC", "dynamic in static PLY [%]",
                 "frames/s on", "frames/s off"], rows)
    if ratios:
        print(f"dynamic sequences: mean ATE on {np.mean(ate_on):.2f} cm, off {np.mean(ate_off):.2f} cm, "
              f"ratio of the means {np.mean(ate_off) / max(np.mean(ate_on), 1e-9):.2f}, "
              f"mean of the ratios {np.mean(ratios):.2f}")


if __name__ == "__main__":
    main()
