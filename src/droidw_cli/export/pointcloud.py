"""Keyframe point clouds from a run: the dynamic-static composite map.

Every 1/8-grid pixel p of keyframe k with disparity d becomes the world point
X = G_k⁻¹ · Π⁻¹(p, d).  A run records M_k, every pixel of keyframe k that was
ever masked dynamic, and the object id of each (``dynamic``, ``object_ids``
in ``keyframes.npz``).

* **static**: p outside M_k and the pixels BA zeroed (``masked``, where the
  run has it: the conservative in-loop masks), grown by ``dynamic_margin``
  cells (a 1/8-grid cell on a mover's outline mixes mover and background),
  its uncertainty u is under
  ``max_uncertainty``, *and*
  several views agree on it: projected into the neighbouring keyframes
  k ± 1 … k ± ``radius`` (those that exist), its disparity matches theirs
  (bilinearly sampled) within ``rel_tol`` in at least ``min_views`` of them.
  A run with too few keyframes for that test (one keyframe: a camera that
  never moved enough to build a map) has no multi-view map: building its
  cloud is a user error, unless ``min_views`` is lowered (0: no test).
* **dynamic**: p ∈ M_k, tagged with its keyframe's time t and its object id
  (−1 where the mask has no tracked object).  A run without masks
  (``dynamics.mode=none``) has no M_k; its dynamic points are then the
  non-static ones.

``droidw export ply``, ``export render`` and ``view`` all take their points
from :meth:`Cloud.part` (``view`` shows a run too short for the test without points).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from droidw_cli.ba.uncertainty import weighting_input
from droidw_cli.errors import InputError
from droidw_cli.geometry.camera import BA_SCALE, scale_intrinsics
from droidw_cli.io.trajectory import atomic_write_bytes


@dataclass(frozen=True)
class CloudParams:
    """``max_uncertainty`` applies to u as the BA weighting sees it: with ``relative`` (the tracker's
    default ``uncertainty.mode``), u rescaled so that its median over all keyframes is 0.75, so the
    threshold sits at the clamp mapping's knee (0.8) whatever level XFeat's u settles at."""

    max_uncertainty: float = 0.8
    relative: bool = True
    min_views: int = 2
    radius: int = 2
    rel_tol: float = 0.05
    stride: int = 1  # use every N-th keyframe
    dynamic_margin: int = 0  # static points keep this many grid cells away from M_k (mixed outline cells)


@dataclass(frozen=True)
class Cloud:
    """Points (P, 3) float32, colours (P, 3) uint8, keyframe time (P,), uncertainty (P,), static flag (P,),
    dynamic flag (P,) and object id (P,) int32 (−1: none)."""

    xyz: np.ndarray
    rgb: np.ndarray
    time: np.ndarray
    uncertainty: np.ndarray
    static: np.ndarray
    dynamic: np.ndarray
    object_id: np.ndarray

    def select(self, mask: np.ndarray) -> "Cloud":
        return Cloud(self.xyz[mask], self.rgb[mask], self.time[mask], self.uncertainty[mask], self.static[mask],
                     self.dynamic[mask], self.object_id[mask])

    def part(self, what: str) -> "Cloud":
        """The points of ``--what`` ``static``, ``dynamic`` or ``all`` (static and dynamic: not the points
        rejected for their uncertainty or too few agreeing views)."""
        masks = {"static": self.static, "dynamic": self.dynamic, "all": self.static | self.dynamic}
        if what not in masks:
            raise ValueError(f"unknown point selection {what!r} (expected static, dynamic or all)")
        return self.select(masks[what])


def _backproject(disps: torch.Tensor, k8: torch.Tensor) -> torch.Tensor:
    """(K, h, w) disparities → (K, h, w, 3) camera points."""
    _, h, w = disps.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    z = 1.0 / disps.double().clamp(min=1e-6)
    x = (xs - k8[2]) / k8[0] * z
    y = (ys - k8[3]) / k8[1] * z
    return torch.stack([x, y, z], -1)


def max_support(num_kf: int, radius: int) -> int:
    """The most neighbours any point can be compared with: k ± 1 … k ± ``radius`` within the run."""
    return max(0, min(num_kf - 1, 2 * radius))


def check_min_views(num_kf: int, params: CloudParams) -> None:
    """Raise :class:`InputError` when no point of a ``num_kf``-keyframe run can pass the multi-view test."""
    most = max_support(num_kf, params.radius)
    if params.min_views <= most:
        return
    if params.min_views > 2 * params.radius:
        raise InputError(f"--min-views {params.min_views} can never be met: each point is compared "
                         f"with at most {2 * params.radius} neighbouring keyframes (±{params.radius})")
    raise InputError(f"the run has {num_kf} keyframe{'s' if num_kf != 1 else ''}, so no point can be confirmed by "
                     f"{params.min_views} other keyframes (--min-views {params.min_views}), at most {most}: there is "
                     f"no multi-view map (a camera that barely moves keeps one keyframe); track a longer clip with "
                     f"camera motion, or lower --min-views (0 keeps every keyframe point, unchecked)")


def multiview_support(disps: np.ndarray, poses_c2w: np.ndarray, k8: np.ndarray, radius: int, rel_tol: float) -> np.ndarray:
    """(K, h, w) count of neighbouring keyframes that agree with each pixel's depth (at most
    :func:`max_support`; all 0 for a single keyframe)."""
    d = torch.from_numpy(disps).double()
    kf, h, w = d.shape
    cam = _backproject(d, torch.from_numpy(k8))
    c2w = torch.from_numpy(poses_c2w).double()
    world = torch.einsum("kab,khwb->khwa", c2w[:, :3, :3], cam) + c2w[:, None, None, :3, 3]
    w2c = torch.linalg.inv(c2w)
    support = torch.zeros(kf, h, w, dtype=torch.int32)
    # a loop over view offsets, not pixels; an offset of kf or more has no keyframe pair
    for off in [o for r in range(1, min(radius, kf - 1) + 1) for o in (r, -r)]:
        src = torch.arange(max(0, -off), min(kf, kf - off))
        dst = src + off
        p = torch.einsum("kab,khwb->khwa", w2c[dst, :3, :3], world[src]) + w2c[dst, None, None, :3, 3]
        z = p[..., 2]
        u = k8[0] * p[..., 0] / z.clamp(min=1e-6) + k8[2]
        v = k8[1] * p[..., 1] / z.clamp(min=1e-6) + k8[3]
        grid = torch.stack([2 * u / (w - 1) - 1, 2 * v / (h - 1) - 1], -1)
        sampled = F.grid_sample(d[dst, None], grid, mode="bilinear", align_corners=True, padding_mode="zeros")[:, 0]
        proj_disp = 1.0 / z.clamp(min=1e-6)
        inside = (z > 1e-3) & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1) & (sampled > 0)
        agree = inside & ((proj_disp - sampled).abs() <= rel_tol * sampled)
        support[src] += agree.int()
    return support.numpy()


def build_cloud(npz: dict, params: CloudParams) -> Cloud:
    """All keyframe points of a run (every ``params.stride``-th keyframe), with static flags.

    Raises :class:`InputError` when the run has too few keyframes for ``params.min_views``
    (:func:`check_min_views`): an empty static cloud would hide that the test could not be run.
    """
    disps = np.asarray(npz["disps"], dtype=np.float32)
    poses = np.asarray(npz["poses_c2w"], dtype=np.float64)
    kf, h, w = disps.shape
    if kf == 0:
        raise InputError("the run has no keyframes")
    check_min_views(kf, params)
    k8 = scale_intrinsics(np.asarray(npz["intrinsics"], dtype=np.float64), BA_SCALE)
    support = multiview_support(disps, poses, k8, params.radius, params.rel_tol)
    unc = np.asarray(npz["uncertainty"], dtype=np.float32) if "uncertainty" in npz else np.zeros_like(disps)
    cam = _backproject(torch.from_numpy(disps), torch.from_numpy(k8)).numpy()
    world = np.einsum("kab,khwb->khwa", poses[:, :3, :3], cam) + poses[:, None, None, :3, 3]
    images = np.asarray(npz["images"])
    rgb = np.stack([cv2.resize(im, (w, h), interpolation=cv2.INTER_AREA) for im in images])
    times = np.broadcast_to(np.asarray(npz["timestamps"], dtype=np.float64)[:, None, None], (kf, h, w))
    seen = unc if not (params.relative and "uncertainty" in npz) else weighting_input(torch.from_numpy(unc), "relative").numpy()
    static = (seen < params.max_uncertainty) & (support >= params.min_views)
    if "dynamic" in npz:
        dynamic = np.asarray(npz["dynamic"], dtype=bool)
        ids = np.asarray(npz["object_ids"], dtype=np.int32)
        away = dynamic | np.asarray(npz["masked"], dtype=bool) if "masked" in npz else dynamic
        if params.dynamic_margin > 0 and away.any():
            kernel = np.ones((2 * params.dynamic_margin + 1,) * 2, np.uint8)
            away = np.stack([cv2.dilate(m.astype(np.uint8), kernel) > 0 for m in away])
        static &= ~away
    else:
        dynamic, ids = ~static, np.full(static.shape, -1, dtype=np.int32)
    keep = np.zeros(kf, dtype=bool)
    keep[:: max(1, params.stride)] = True
    sel = np.broadcast_to(keep[:, None, None], (kf, h, w))
    return Cloud(world[sel].astype(np.float32), rgb[sel].astype(np.uint8), times[sel].copy(), unc[sel].copy(),
                 static[sel].copy(), dynamic[sel].copy(), ids[sel].copy())


def write_ply(path, cloud: Cloud, with_time: bool, with_flag: bool = False) -> int:
    """Write a binary little-endian PLY; returns the point count.

    Vertex properties: ``x y z red green blue``; with ``with_time`` also
    ``t`` (keyframe time, s), ``object_id`` (int, −1 none) and ``uncertainty``;
    with ``with_flag`` also ``dynamic`` (uchar 0/1).
    """
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")]
    if with_time:
        fields += [("t", "<f8"), ("object_id", "<i4"), ("uncertainty", "<f4")]
    if with_flag:
        fields += [("dynamic", "u1")]
    data = np.empty(len(cloud.xyz), dtype=fields)
    data["x"], data["y"], data["z"] = cloud.xyz[:, 0], cloud.xyz[:, 1], cloud.xyz[:, 2]
    data["red"], data["green"], data["blue"] = cloud.rgb[:, 0], cloud.rgb[:, 1], cloud.rgb[:, 2]
    if with_time:
        data["t"], data["object_id"], data["uncertainty"] = cloud.time, cloud.object_id, cloud.uncertainty
    if with_flag:
        data["dynamic"] = cloud.dynamic.astype(np.uint8)
    ply_types = {"<f4": "float", "u1": "uchar", "<f8": "double", "<i4": "int"}
    header = ["ply", "format binary_little_endian 1.0", "comment written by droidw", f"element vertex {len(data)}"]
    header += [f"property {ply_types[t]} {n}" for n, t in fields] + ["end_header"]
    atomic_write_bytes(path, ("\n".join(header) + "\n").encode("ascii") + data.tobytes())
    return int(len(data))
