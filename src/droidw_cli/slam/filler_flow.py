"""The filler's flows keyframe → frame, computed ahead of time on a worker thread.

A target p*_kt (:meth:`~droidw_cli.correspondence.base.CorrespondenceSource.quick_target`)
depends on the two images only, so it can be computed as soon as both exist:
a → t when frame t arrives (a is the newest keyframe then), b → t when the
keyframe b after the gap has settled in the buffer, one keyframe later.  The
gap is solved ``lag`` keyframes after a, by which time the worker has
usually finished.  The results are the very tensors a synchronous call would
return (DIS is deterministic), so only the wall time changes: OpenCV
releases the GIL and DIS runs on one core, which on two cores overlaps the
flows with the window BA (torch, one thread) instead of adding to it.

Only sources that declare ``concurrent_quick_target`` (their ``quick_target``
may run on another thread while ``match`` runs on the main one) get a worker;
every call of theirs then goes through that one worker, so ``quick_target``
never runs twice at once.  Others are called synchronously when the gap is
solved.  A guess for b that keyframe removal later drops is wasted work, not
a wrong result: targets are looked up by (keyframe, frame).
"""

from __future__ import annotations

from concurrent.futures import Future, ThreadPoolExecutor

import cv2
import numpy as np
from torch import Tensor


def grey(image: np.ndarray) -> np.ndarray:
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


class AheadTargets:
    """Quick targets keyframe → frame by frame index, computed ahead where the source allows."""

    def __init__(self, correspondence, ahead: bool = True):
        self.corr = correspondence
        self.ahead = bool(ahead and getattr(correspondence, "concurrent_quick_target", False))
        self._pool: ThreadPoolExecutor | None = None
        self._jobs: dict[int, dict[int, Future]] = {}  # frame index → {keyframe frame index → job}

    def submit(self, key: int, key_image: np.ndarray, frame: int, image: np.ndarray) -> None:
        """Start target key → frame on the worker (nothing without one, or when it is already there)."""
        if not self.ahead:
            return
        jobs = self._jobs.setdefault(frame, {})
        if key not in jobs:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="droidw-filler")
            jobs[key] = self._pool.submit(self._target, key_image, image)

    def get(self, pairs: list[tuple[int, np.ndarray, int, np.ndarray]]) -> list[Tensor]:
        """Targets of (key, key image, frame, image) pairs, in order: started ones awaited, others computed.

        Images are RGB or grey; the source gets both grey."""
        for pair in pairs:
            self.submit(*pair)
        if not self.ahead:
            return [self._target(ki, im) for _, ki, _, im in pairs]
        return [self._jobs[f][k].result() for k, _, f, _ in pairs]

    def _target(self, key_image: np.ndarray, image: np.ndarray) -> Tensor:
        return self.corr.quick_target(grey(key_image), grey(image))

    def forget(self, frames) -> None:
        """Drop the jobs of these frames (their gap is solved); unfinished ones are cancelled."""
        for f in frames:
            for job in self._jobs.pop(f, {}).values():
                job.cancel()

    def close(self) -> None:
        """Stop the worker (waits for the job it is running); later calls compute synchronously."""
        self._jobs.clear()
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
        self.ahead = False
