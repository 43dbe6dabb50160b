"""The correspondence-source interface.

A correspondence source gives, for a directed edge (i, j) of the frame
graph, the dense target p*_ij (where each 1/8-grid cell of frame i lands in
frame j, in grid coordinates of frame j) and a confidence w_ij ∈ [0, 1].
droidw's built-in source is classical optical flow (OpenCV DIS); a plugin
implementing :class:`CorrespondenceSource` can replace it (registered under
the ``droidw.correspondence`` entry-point group).
"""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass
from typing import Any, Callable, Sequence

import numpy as np
import torch

from droidw_cli.correspondence.confidence import invert_flow
from droidw_cli.correspondence.grid import mean_length, validate_image
from droidw_cli.runtime.threads import usable_cores


@dataclass(frozen=True)
class Correspondence:
    """Dense correspondence of one directed edge i → j.

    Attributes:
        flow: (H, W, 2) float32 numpy, full-resolution flow i → j (x, y in px).
        target: (H/8, W/8, 2) float32 tensor, p*_ij = g + f̄/8 in 1/8-grid
            coordinates of frame j (see :mod:`droidw_cli.correspondence.grid`).
        weight: (H/8, W/8, 2) float32 tensor in [0, 1]; both channels equal.
    """

    flow: np.ndarray
    target: torch.Tensor
    weight: torch.Tensor

    @property
    def mean_flow(self) -> float:
        """Mean flow magnitude over all pixels, full-resolution px."""
        return mean_length(self.flow)


@dataclass(frozen=True)
class MatchCall:
    """One call of :meth:`CorrespondenceSource.match_all`: ``match(i, j, init_flow)``, or
    ``match_pair`` (both directions) when ``both``."""

    image_i: np.ndarray
    image_j: np.ndarray
    init_flow: np.ndarray | None = None
    both: bool = False


class CorrespondenceSource(ABC):
    """Dense targets and confidences between two frames."""

    name: str = ""
    #: ``quick_target`` may run on a worker thread while the other methods run on the main one
    #: (the trajectory filler then computes its flows ahead of time); calls of ``quick_target``
    #: itself never overlap.  False: the filler calls it synchronously.
    concurrent_quick_target: bool = False
    #: ``match`` and ``match_pair`` may run on several threads at once (their state is per thread):
    #: :meth:`match_all` then spreads its calls over the usable cores
    concurrent_match: bool = False

    @abstractmethod
    def match(self, image_i: np.ndarray, image_j: np.ndarray, init_flow: np.ndarray | None = None) -> Correspondence:
        """Correspondence i → j.

        Args:
            image_i, image_j: (H, W, 3) uint8 RGB at the working resolution,
                H and W multiples of 8.
            init_flow: optional (H, W, 2) float32 full-resolution flow i → j to
                start from (e.g. induced by the current poses and depths).
        """

    def match_pair(self, image_i: np.ndarray, image_j: np.ndarray,
                   init_flow: np.ndarray | None = None) -> tuple[Correspondence, Correspondence]:
        """Both directions (i → j, j → i) of an edge pair.

        The default runs :meth:`match` twice; sources whose confidence already
        needs the backward flow (DIS's forward-backward check) override it to
        reuse one forward-backward pair for both.  ``init_flow`` is i → j.
        """
        back = None if init_flow is None else invert_flow(np.asarray(init_flow, dtype=np.float32))
        return self.match(image_i, image_j, init_flow), self.match(image_j, image_i, back)

    def quick_target(self, image_i: np.ndarray, image_j: np.ndarray) -> torch.Tensor:
        """A cheap target p*_ij (H/8, W/8, 2) with no confidence, for the trajectory filler.

        The filler refines one pose per frame against fixed keyframes and weights
        pixels by its own robust loss, so it needs many correspondences cheaply,
        not a confidence.  The default is :meth:`match`'s target.
        """
        return self.match(image_i, image_j).target

    def mean_flow(self, image_i: np.ndarray, image_j: np.ndarray) -> float:
        """A cheap estimate of the mean flow magnitude i → j in full-res px (for the motion filter).

        The default runs :meth:`match`; sources override it with something cheaper.
        """
        return self.match(image_i, image_j).mean_flow

    def stages(self, call: MatchCall) -> tuple[list[Callable[[], Any]], Callable[[list[Any]], list[Callable[[], Correspondence]]]]:
        """A call split for :meth:`match_all`: independent first-stage jobs (e.g. one per flow
        direction), and from their results, in order, one job per correspondence the call makes.

        The default has one first-stage job (the whole :meth:`match` or :meth:`match_pair`) and
        second-stage jobs that only hand its correspondences on.
        """
        def whole() -> tuple[Correspondence, ...]:
            if call.both:
                return self.match_pair(call.image_i, call.image_j, call.init_flow)
            return (self.match(call.image_i, call.image_j, call.init_flow),)

        def finish(outs: list[Any]) -> list[Callable[[], Correspondence]]:
            return [lambda c=c: c for c in outs[0]]
        return [whole], finish

    def match_all(self, calls: Sequence[MatchCall], derive: Callable[[Correspondence], Any] | None = None,
                  serial: bool = False) -> list[list[tuple[Correspondence, Any]]]:
        """Several :meth:`match` / :meth:`match_pair` calls; per call, its correspondences with ``derive`` of each.

        ``derive`` (optional) runs beside the job that made the correspondence
        (for per-edge maps such as the epipolar distances), None otherwise.
        Each call is split by :meth:`stages`; with ``concurrent_match`` the
        jobs of each stage are pulled from one queue by the calling thread and
        a pool of worker threads, as many at once as there are usable cores
        (a keyframe's three forward-backward pairs are six flows, three per
        core, rather than one pair on one core and two on the other).  The
        results come back in the order of ``calls`` either way, the same as
        one after the other.  ``serial``: every job on the calling thread (a
        caller that is itself a background thread).
        """
        split = [self.stages(c) for c in calls]
        first = self._run_jobs([job for jobs, _ in split for job in jobs], serial)
        second, counts, at = [], [], 0
        for jobs, finish in split:
            made = finish(first[at:at + len(jobs)])
            at += len(jobs)
            counts.append(len(made))
            second += [(lambda make=make: self._derived(make(), derive)) for make in made]
        results = self._run_jobs(second, serial)
        out, at = [], 0
        for n in counts:
            out.append(results[at:at + n])
            at += n
        return out

    @staticmethod
    def _derived(c: Correspondence, derive: Callable[[Correspondence], Any] | None) -> tuple[Correspondence, Any]:
        return c, None if derive is None else derive(c)

    def _run_jobs(self, jobs: list[Callable[[], Any]], serial: bool = False) -> list[Any]:
        """Run the jobs (on the calling thread and, with ``concurrent_match``, workers); results in order.

        Which thread runs which job varies from run to run; the results do not
        (each job depends on its inputs only).  The first error is raised once
        every job has finished or been skipped.
        """
        workers = min(len(jobs), usable_cores())
        if serial or not self.concurrent_match or workers < 2:
            return [job() for job in jobs]
        size, pool = getattr(self, "_match_pool", (0, None))
        if size < workers - 1:
            size, pool = workers - 1, ThreadPoolExecutor(workers - 1, thread_name_prefix="droidw-match")
            self._match_pool = (size, pool)
        results: list[Any] = [None] * len(jobs)
        errors: list[BaseException] = []
        queue = iter(range(len(jobs)))
        lock = threading.Lock()

        def drain() -> None:
            while not errors:
                with lock:
                    n = next(queue, None)
                if n is None:
                    return
                try:
                    results[n] = jobs[n]()
                except BaseException as e:  # re-raised on the calling thread below
                    errors.append(e)

        helpers = [pool.submit(drain) for _ in range(workers - 1)]
        drain()
        wait(helpers)  # every job has finished when this returns or raises
        if errors:
            raise errors[0]
        return results

    def match_many(
        self,
        pairs: Sequence[tuple[np.ndarray, np.ndarray]],
        init_flows: Sequence[np.ndarray | None] | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Targets and weights of several edges, stacked as (E, H/8, W/8, 2) each.

        Args:
            pairs: (image_i, image_j) per edge, all of the same size.
            init_flows: None, or one optional initial flow per edge.
        """
        if len(pairs) == 0:
            raise ValueError("match_many needs at least one pair")
        if init_flows is not None and len(init_flows) != len(pairs):
            raise ValueError(f"got {len(init_flows)} init_flows for {len(pairs)} pairs")
        shape = validate_image(pairs[0][0], "image_i").shape[:2]
        targets, weights = [], []
        for k, (image_i, image_j) in enumerate(pairs):
            if image_i.shape[:2] != shape or image_j.shape[:2] != shape:
                raise ValueError(f"pair {k} has size {image_i.shape[:2]}/{image_j.shape[:2]}, expected {shape}")
            corr = self.match(image_i, image_j, None if init_flows is None else init_flows[k])
            targets.append(corr.target)
            weights.append(corr.weight)
        return torch.stack(targets), torch.stack(weights)
