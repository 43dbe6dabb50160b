"""Keyframe candidates decided ahead of the frontend; a new keyframe's first edge and features made early.

Once the map is initialised, the motion filter depends on the images alone
(the flow from the last candidate, which becomes the new reference whatever
the frontend later does with it), so it can run on the prefetch thread,
frames ahead of the tracker.  When it flags a candidate c there, the scout
also matches c with the previous candidate p, both directions from one
forward-backward DIS pair, without an initial flow.  That is exactly the
frontend's edge pair (k, k − 1) once c becomes keyframe k: keyframe removal
only ever drops the second-newest keyframe, so the newest is always the last
candidate (with ``frontend.skip_doomed`` the tracker may pass a candidate
over; the next one's early match then goes unused and the frontend matches it
itself).  The pair is then computed on the second core while the main thread
runs the previous keyframe's window BA (on one torch thread), instead of after
it.  The result is the same as on the main thread: DIS depends on its two images and
the start only (:mod:`droidw_cli.correspondence.dis`).
The candidate's features (the uncertainty's input) are extracted there too,
before the match.

Before initialisation the filter's rule (median flow, lower quartile after
``max_gap`` frames) depends on whether the frontend has initialised, which
it may do at any candidate: the scout then waits after each candidate until
the tracker has taken it (:meth:`Scout.taken`), so it decides every frame as
the main thread would have.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from functools import partial
from typing import Any

import numpy as np

from droidw_cli.runtime.timing import StageTimer
from droidw_cli.slam.motion_filter import MotionFilter

#: what the scout hands on per frame: (frame, image, depth, is the frame a keyframe candidate)
Scouted = tuple[Any, np.ndarray, Any, bool]


class Scout:
    """The motion filter, run wherever :meth:`frames` is iterated, and early work on a worker of its own.

    ``prematch(image_c, image_p, start)`` returns the frontend's match of the pair
    (its :meth:`~droidw_cli.slam.frontend.Frontend.match_adjacent`), and
    ``prefeatures(image_c)`` the candidate's features; None: not done early.
    The early work runs only between :meth:`release` and :meth:`hold`: the
    tracker releases it while its main thread runs BA on one core, and holds
    it while it matches on both.
    """

    def __init__(self, mfilter: MotionFilter, timer: StageTimer | None = None,
                 prematch: Callable[[np.ndarray, np.ndarray], Any] | None = None,
                 prefeatures: Callable[[np.ndarray], Any] | None = None):
        self.mfilter = mfilter
        self._timer = timer or StageTimer()  # "motion_filter": its time on the thread that iterates frames()
        self._prematch = prematch
        self._prefeatures = prefeatures
        self._initialised = False
        self._flows: dict[int, float] = {}  # candidate frame → its mean flow from the previous candidate (grid px)
        # candidate frame → (previous candidate, the motion filter's flow from it, half size): see start()
        self._starts: dict[int, tuple[int, np.ndarray]] = {}
        self._turn = threading.Event()  # set: the tracker has taken the last candidate
        self._turn.set()
        self._closed = False
        self._lock = threading.Lock()
        self._released = False
        # ("features", candidate frame) or ("match", candidate frame, previous candidate frame) →
        # the job not started yet, or its future once started
        self._pending: dict[tuple, Callable[[], Any]] = {}
        self._started: dict[tuple, Future] = {}
        early = prematch is not None or prefeatures is not None
        self._pool = ThreadPoolExecutor(1, thread_name_prefix="droidw-scout") if early else None

    def frames(self, items: Iterable[tuple[Any, np.ndarray, Any]]) -> Iterator[Scouted]:
        """(frame, image, depth) items → (frame, image, depth, is_candidate), in order.

        Once the map is initialised the input's last frame is always a candidate: frames after the last
        keyframe have only one keyframe to be placed from, and no later one to bound them (on the ``ride``
        preset with ``motion_filter.max_gap`` 13 the last 5 frames, placed from the keyframe before them alone,
        drifted to 1.7 m while the keyframes read 2.6 cm ATE)."""
        previous: tuple[int, np.ndarray] | None = None
        for (frame, image, depth), last in _with_last(items):
            initialised = self._initialised
            with self._timer("motion_filter"):
                candidate, stats = self.mfilter.check(image, initialised)
            candidate = candidate or (last and initialised)
            if not candidate:
                yield frame, image, depth, False
                continue
            self.mfilter.accept(image)
            self._flows[frame.index] = stats.mean
            if previous is not None and self.mfilter.accepted_flow is not None:
                with self._lock:
                    self._starts[frame.index] = (previous[0], self.mfilter.accepted_flow)
            if initialised:
                self._queue(frame.index, image, previous)
                previous = (frame.index, image)
                yield frame, image, depth, True
                continue
            previous = (frame.index, image)
            self._turn.clear()
            yield frame, image, depth, True
            while not self._turn.wait(0.05):  # until the tracker has added it (or stopped)
                if self._closed:
                    return

    def _queue(self, frame: int, image: np.ndarray, previous: tuple[int, np.ndarray] | None) -> None:
        """The early work of candidate ``frame``, started now if released."""
        jobs = {}
        if self._prefeatures is not None:  # first: the BA needs them as soon as the match
            jobs[("features", frame)] = partial(self._prefeatures, image)
        if self._prematch is not None and previous is not None:
            start = self.start(frame, previous[0])
            jobs[("match", frame, previous[0])] = partial(self._prematch, image, previous[1], start)
        with self._lock:
            self._pending.update(jobs)
            if self._released:
                self._start()

    def start(self, frame: int, previous: int) -> np.ndarray | None:
        """The motion filter's flow (half size, px) from candidate ``previous`` to candidate ``frame``, when
        ``previous`` was ``frame``'s reference: it starts the match of the pair (:meth:`Frontend.match_adjacent`)."""
        with self._lock:
            got = self._starts.get(frame)
        return got[1] if got is not None and got[0] == previous else None

    def flow(self, frame: int) -> float:
        """Candidate ``frame``'s mean flow from the previous candidate in grid px (once; 0 for the first).
        The tracker asks in frame order: the starts of earlier candidates are no longer needed."""
        with self._lock:
            for old in [f for f in self._starts if f < frame]:
                del self._starts[old]
        return self._flows.pop(frame, 0.0)

    def taken(self, initialised: bool) -> None:
        """The tracker has added the last candidate; ``initialised``: the frontend's state after it."""
        self._initialised = self._initialised or initialised
        self._turn.set()

    def hold(self) -> None:
        """Start no early work until :meth:`release` (running jobs go on)."""
        with self._lock:
            self._released = False

    def release(self) -> None:
        """Start the early work of the candidates flagged so far, and of later ones as they come."""
        with self._lock:
            self._released = True
            self._start()

    def _start(self) -> None:
        for key, job in self._pending.items():
            self._started[key] = self._pool.submit(job)
        self._pending.clear()

    def _take(self, key: tuple) -> Future | None:
        """The started job ``key`` (once); jobs of its kind for this or earlier candidates are forgotten
        (the tracker has done them itself)."""
        with self._lock:
            future = self._started.pop(key, None)
            for table in (self._pending, self._started):
                for old in [old for old in table if old[0] == key[0] and old[1] <= key[1]]:
                    del table[old]
        return future

    def matched(self, frame_i: int, frame_j: int) -> Any | None:
        """The early match of candidate frame ``frame_i`` with its predecessor ``frame_j`` (waiting
        for it when it has started), or None when it has not started."""
        future = self._take(("match", frame_i, frame_j))
        return None if future is None else future.result()

    def features(self, frame: int) -> Future | None:
        """The future of candidate ``frame``'s early features, or None when they have not started."""
        return self._take(("features", frame))

    def close(self) -> None:
        """Stop waiting for the tracker (so that the prefetch thread can end) and stop the worker."""
        self._closed = True
        self._turn.set()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)


def _with_last(items: Iterable) -> Iterator[tuple[Any, bool]]:
    """(item, whether it is the last one) for each item, one item behind the input."""
    it = iter(items)
    try:
        held = next(it)
    except StopIteration:
        return
    for item in it:
        yield held, False
        held = item
    yield held, True
