"""Where the walkers walk: loops on the floor, and walkers that keep apart.

Each walker follows its own ellipse (:class:`~droidw_cli.synth.paths.EllipseWalk`).
Loops drawn one by one may cross at the same moment, and two bodies would then
pass through each other: one blob, at one depth, on one spot of the floor, which
no two people do and no tracker could tell apart.  So the walkers are placed in
order (walker 0, the close one, first) and walker i must keep its body axis at
least ``CLEARANCE`` from every walker placed before it, at every frame:

    min_t min_{j<i} |p_i(t) − p_j(t)| ≥ c.

A walker that breaks this is drawn again.  Draw j takes the loop stream
``default_rng([seed, TAG_PATH + i, TAG_APART, j])``; the first draws keep the
far region and the usual loop size, later ones (``SCHEDULE``) allow smaller
loops and a region that starts nearer the camera, but never nearer than
``CAMERA_GAP`` to the camera's position at any frame.  Each loop is tried with
``PHASES`` starting points in both directions of travel before the next draw:
a loop that crosses another walker's path can usually be walked so as to reach
the crossing at another time.  The first timing that holds the clearance is
kept, unless the scene refuses it (walker coverage of the image above its cap);
after ``DRAWS`` draws the admitted one that kept farthest apart is (walkers may
then come closer than the clearance: many walkers in a small room).  A walker
that already keeps apart keeps its loop, so scenes without meetings do not
change.  Opt-in: ``SynthConfig.apart`` (``droidw synth --apart``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import numpy as np

from droidw_cli.synth import layout
from droidw_cli.synth.paths import EllipseWalk, make_walk

FAR_Y = 2.8  # the far walkers' first draws stay beyond this y (the camera is at y ≈ 0.5-1.3)
CLEARANCE = 0.7  # metres between two walkers' body axes (bodies are ~0.5 m wide)
CAMERA_GAP = 1.4  # a redrawn walker's axis stays this far from the camera's position
DRAWS = 1600
PHASES = 12
TAG_APART = 300
#: (loop size factor, near edge y of the region) for successive eighths of the draws
SCHEDULE = ((1.0, FAR_Y), (0.8, FAR_Y), (1.0, 2.3), (0.8, 2.3), (0.8, 1.9), (0.6, 1.9), (0.6, 2.3), (0.5, 1.9))


def extent(e1: np.ndarray, a: float, b: float) -> np.ndarray:
    """Half extents in x, y of the ellipse a cos(s) e₁ + b sin(s) e₂ (e₂ = e₁ turned 90°)."""
    e2 = np.array([-e1[1], e1[0]])
    return np.sqrt((a * e1) ** 2 + (b * e2) ** 2)


def shrink(e1: np.ndarray, a: float, b: float, lo: np.ndarray, hi: np.ndarray,
           a_min: float = 0.5, b_min: float = 0.3) -> tuple[float, float]:
    """Shrink (a, b) (not below a_min, b_min) until the ellipse fits in the rectangle's size."""
    for _ in range(60):
        if np.all(2 * extent(e1, a, b) <= hi - lo) or (a <= a_min and b <= b_min):
            break
        a, b = max(a_min, 0.95 * a), max(b_min, 0.95 * b)
    return a, b


def slide(centre: np.ndarray, direction: np.ndarray, ext: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Move ``centre`` along ``direction`` the least so that centre ± ext lies in [lo, hi]; clip if impossible."""
    s_lo, s_hi = -np.inf, np.inf
    for c in range(2):
        a, b = lo[c] + ext[c] - centre[c], hi[c] - ext[c] - centre[c]
        if abs(direction[c]) < 1e-9:
            if a > 1e-9 or b < -1e-9:
                s_lo, s_hi = 1.0, 0.0  # infeasible along this direction
            continue
        s1, s2 = sorted((a / direction[c], b / direction[c]))
        s_lo, s_hi = max(s_lo, s1), min(s_hi, s2)
    if s_lo <= s_hi:
        return centre + float(np.clip(0.0, s_lo, s_hi)) * direction
    return np.clip(centre, lo + ext, np.maximum(lo + ext, hi - ext))


def far_walk(rng: np.random.Generator, room: np.ndarray, scale: float = 1.0, near_y: float = FAR_Y) -> EllipseWalk:
    """A loop in the part of the room beyond ``near_y`` (by default at least ~1.4 m in front of the camera),
    its half axes ``scale`` times the usual 0.6-1.5 × 0.3-0.6 m."""
    lo, hi = layout.walker_region(room, near_y)
    ang = rng.uniform(-0.4, 0.4) + (np.pi / 2 if rng.uniform() < 0.25 else 0.0)
    e1 = np.array([np.cos(ang), np.sin(ang)])
    a, b = shrink(e1, scale * rng.uniform(0.6, 1.5), scale * rng.uniform(0.3, 0.6), lo, hi, 0.5 * scale, 0.3 * scale)
    centre = slide(rng.uniform(lo, hi), np.array([1.0, 0.0]), extent(e1, a, b), lo, hi)
    centre = slide(centre, np.array([0.0, 1.0]), extent(e1, a, b), lo, hi)
    return make_walk(centre, e1, a, b, rng.uniform(0.6, 1.2), int(rng.choice([-1, 1])), rng.uniform(0, 2 * np.pi), 0.0)


def _timings(loop: EllipseWalk):
    """The loop walked from ``PHASES`` starting points, in its own direction and then the other."""
    for sign in (1.0, -1.0):
        for k in range(PHASES):
            yield dataclasses.replace(loop, omega=sign * loop.omega, s0=loop.s0 + 2.0 * np.pi * k / PHASES)


def _gap(path: np.ndarray, placed: list[np.ndarray]) -> float:
    """The smallest floor distance, over the frames, between ``path`` (T, 2) and any placed path."""
    return float(min(np.linalg.norm(path - q, axis=1).min() for q in placed))


def _redraw(index: int, walk: EllipseWalk, placed: list[np.ndarray], t: np.ndarray, cam_xy: np.ndarray,
            room: np.ndarray, seed: int, admits: Callable[[EllipseWalk], bool]) -> EllipseWalk:
    path = walk.state(t)[1][:, :2]
    best = (_gap(path, placed), walk)
    for j in range(DRAWS):
        scale, near_y = SCHEDULE[j * len(SCHEDULE) // DRAWS]
        loop = far_walk(np.random.default_rng([seed, layout.TAG_PATH + index, TAG_APART, j]), room, scale, near_y)
        for candidate in _timings(loop):
            path = candidate.state(t)[1][:, :2]
            if np.linalg.norm(path - cam_xy, axis=1).min() < CAMERA_GAP:
                continue
            gap = _gap(path, placed)
            if gap > best[0] and admits(candidate):
                if gap >= CLEARANCE:
                    return candidate
                best = (gap, candidate)
    return best[1]


def keep_apart(walks: list[EllipseWalk], t: np.ndarray, cam_xy: np.ndarray, room: np.ndarray, seed: int,
               admits: Callable[[list[EllipseWalk]], bool] | None = None) -> list[EllipseWalk]:
    """The walks with walkers 1, 2, … redrawn where they come within ``CLEARANCE`` of a walker before them.

    ``t`` are the walker times of every frame, ``cam_xy`` the camera's floor position at them (T, 2).
    ``admits(walks)`` may refuse a redrawn walker that keeps apart (the scene caps the walkers'
    coverage of the image with it); it sees the walks with the candidate in place.
    """
    if not walks:
        return []
    out = [walks[0]]
    placed = [walks[0].state(t)[1][:, :2]]
    for index, walk in enumerate(walks[1:], 1):
        path = walk.state(t)[1][:, :2]
        if _gap(path, placed) < CLEARANCE:
            def admits_here(candidate: EllipseWalk, index: int = index) -> bool:
                return admits is None or admits(out + [candidate] + list(walks[index + 1:]))
            walk = _redraw(index, walk, placed, t, cam_xy, room, seed, admits_here)
            path = walk.state(t)[1][:, :2]
        out.append(walk)
        placed.append(path)
    return out


def min_gap(walks: list[EllipseWalk], t: np.ndarray) -> float:
    """The smallest distance between any two walkers' body axes over the walker times ``t`` (inf for < 2)."""
    paths = [w.state(t)[1][:, :2] for w in walks]
    gaps = [_gap(p, paths[:i]) for i, p in enumerate(paths) if i > 0]
    return min(gaps, default=float("inf"))
