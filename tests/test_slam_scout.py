"""The scout: the motion filter ahead of the tracker, and early matches of a candidate with its predecessor."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import cv2
import numpy as np

from droidw_cli.config import MotionFilterConfig
from droidw_cli.runtime.prefetch import prefetched
from droidw_cli.slam.motion_filter import MotionFilter
from droidw_cli.slam.scout import Scout


@dataclass(frozen=True)
class _Frame:
    index: int


def _walk(n: int, seed: int = 0) -> list[np.ndarray]:
    """n 384×512 frames of a textured plane whose shift per frame varies (some frames still)."""
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 255, (72, 104), dtype=np.uint8)
    big = cv2.GaussianBlur(cv2.resize(small, (832, 576), interpolation=cv2.INTER_CUBIC), (5, 5), 1.0)
    steps = np.tile([0, 0, 6, 11, 2, 0, 9, 14, 3], n)[:n]
    x = np.cumsum(steps)
    return [np.ascontiguousarray(np.repeat(big[:384, s:s + 512, None], 3, axis=2)) for s in x % 300]


def _sequential(frames: list[np.ndarray], initialise_at: int, max_gap: int = 4) -> list[bool]:
    """The motion filter's decisions without a scout: check, then accept, on one thread."""
    mf = MotionFilter(MotionFilterConfig(max_gap=max_gap))
    out, candidates = [], 0
    for image in frames:
        is_kf, _ = mf.check(image, candidates >= initialise_at)
        if is_kf:
            mf.accept(image)
            candidates += 1
        out.append(is_kf)
    return out


def test_scout_on_a_thread_decides_as_the_tracker_did():
    """Run ahead on the prefetch thread, with the frontend initialising at its third candidate,
    the scout flags exactly the frames the main-thread filter flagged, and matches each candidate
    after initialisation with its predecessor (frame indices), only once released."""
    frames = _walk(60)
    expected = _sequential(frames, initialise_at=3)
    calls = []
    scout = Scout(MotionFilter(MotionFilterConfig(max_gap=4)),
                  prematch=lambda c, p, start: calls.append((c, p)) or ("pair", len(calls)))
    scout.release()
    got, candidates, flagged = [], 0, []
    items = prefetched(scout.frames((_Frame(i), im, None) for i, im in enumerate(frames)), ahead=4)
    for frame, image, depth, is_kf in items:
        got.append(is_kf)
        if is_kf:
            flagged.append(frame.index)
            candidates += 1
            time.sleep(0.01)  # the frontend's work: the scout must not decide ahead before initialisation
            scout.taken(initialised=candidates >= 3)
    scout.close()
    assert got == expected and sum(got) > 6
    later = flagged[3:]  # candidates flagged once the frontend had initialised
    results = [scout.matched(c, p) for c, p in zip(later, flagged[2:])]
    assert all(r is not None and r[0] == "pair" for r in results)
    assert len(calls) == len(later)
    assert all(c is frames[i] and p is frames[j] for (c, p), i, j in zip(calls, later, flagged[2:]))


def test_early_matches_wait_for_release_and_are_forgotten_once_passed():
    frames = _walk(30)
    started = []
    gate = threading.Event()

    def prematch(c, p, start):
        started.append(1)
        gate.wait(5)
        return "done"

    scout = Scout(MotionFilter(MotionFilterConfig(max_gap=2)), prematch=prematch)
    scout.taken(initialised=True)
    flagged = [f.index for f, _, _, kf in scout.frames((_Frame(i), im, None) for i, im in enumerate(frames)) if kf]
    assert len(flagged) >= 4 and not started  # held: nothing started
    assert scout.matched(flagged[1], flagged[0]) is None  # not started: the tracker matches it itself
    scout.release()
    gate.set()
    assert scout.matched(flagged[3], flagged[2]) == "done"  # waits for the running match
    assert scout.matched(flagged[2], flagged[1]) is None  # an earlier candidate's: forgotten
    scout.close()


def test_close_ends_a_scout_that_waits_for_the_tracker():
    """Before initialisation the scout waits after each candidate; closing it lets the thread end."""
    scout = Scout(MotionFilter(MotionFilterConfig(max_gap=2)))
    items = prefetched(scout.frames((_Frame(i), im, None) for i, im in enumerate(_walk(20))), ahead=2)
    first = next(items)
    assert first[3]  # the first frame is always a candidate; the tracker never takes it
    scout.close()
    t = time.perf_counter()
    items.close()
    assert time.perf_counter() - t < 2.0


def test_early_features_come_before_the_match_and_only_after_release():
    frames = _walk(30)
    order = []
    scout = Scout(MotionFilter(MotionFilterConfig(max_gap=2)),
                  prematch=lambda c, p, start: order.append("match") or "m",
                  prefeatures=lambda c: order.append("features") or c.mean())
    scout.taken(initialised=True)
    flagged = [f.index for f, _, _, kf in scout.frames((_Frame(i), im, None) for i, im in enumerate(frames)) if kf]
    assert not order
    scout.release()
    future = scout.features(flagged[2])
    assert future is not None and future.result() == frames[flagged[2]].mean()
    assert scout.matched(flagged[2], flagged[1]) == "m"
    assert scout.features(flagged[1]) is None  # an earlier candidate's: forgotten
    assert scout.matched(flagged[-1], flagged[-2]) == "m"  # the last job: every one before it has run
    scout.close()
    assert order[:3] == ["features", "features", "match"]  # the first candidate has no predecessor to match
    assert order.count("features") == len(flagged) and order.count("match") == len(flagged) - 1


def _scouted(frames: list[np.ndarray], initialise_at: int) -> list[bool]:
    scout = Scout(MotionFilter(MotionFilterConfig(max_gap=50)))
    got, candidates = [], 0
    for frame, image, depth, is_kf in scout.frames((_Frame(i), im, None) for i, im in enumerate(frames)):
        got.append(is_kf)
        if is_kf:
            candidates += 1
            scout.taken(initialised=candidates >= initialise_at)
    scout.close()
    return got


def test_the_last_frame_is_a_candidate_once_initialised():
    """Frames after the last keyframe would have no later keyframe to bound them: once the map is initialised
    the input's last frame is a candidate, even where the camera stood still; before, it is not (a fixed
    camera builds no map at its end)."""
    frames = _walk(40)
    frames += [frames[-1]] * 4  # the camera stops: the motion filter flags none of these
    filtered = _sequential(frames, initialise_at=3, max_gap=50)
    assert not any(filtered[-4:])
    got = _scouted(frames, initialise_at=3)
    assert got[:-1] == filtered[:-1] and got[-1]
    never = _scouted(frames, initialise_at=10**6)
    assert not never[-1] and never == _sequential(frames, initialise_at=10**6, max_gap=50)
