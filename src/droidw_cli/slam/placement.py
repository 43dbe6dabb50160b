"""Placing a new keyframe against its predecessor before its wider edges are started from the map.

A new keyframe k starts at the damped constant-velocity pose
G_k = Exp(λ · Log(G_{k−1} G_{k−2}⁻¹)) G_{k−1}, λ = ``velocity_damping`` (0.5),
with its predecessor's disparity warped into it.  Its wider pairs (k, k − 2)
and its proximity pairs start their flow from the flow the poses and
disparities induce (Eq. 1; :mod:`droidw_cli.slam.starts`), and the warped DIS
keeps 4-8 % of a start's error (``benchmarks/flow_bench.py --seeded`` with the
start's translation 5 % off leaves 0.4 % on the ``drive`` preset at 2 and 8
frames apart).  On a car the damped guess lags half a keyframe step behind,
so that error came back in every (k, k − 2) edge, and the ``drive`` scale
drifted by 3 % over 126 m (seed 3: 17.4 cm ATE; 21.5 and 29.7 cm on seeds 4 and 5).  With 4 iterations
the drive's seeds 1-5 read 6.9 / 3.9 / 5.8 / 5.3 / 4.0 cm (configs/default.yaml, docs/benchmarks.md).

So the pair (k, k − 1) is matched first (usually ready from the scout,
:mod:`droidw_cli.slam.scout`), and ``frontend.place_iters`` BA iterations
(Eq. 4) run over keyframes k − 1 and k alone, k − 1's pose held and its
disparity put back afterwards: only k's pose and disparity move.  They do not
count as window BA iterations (edge ages, the uncertainty's warm-up) and leave
θ alone.  (A motion-only placement along k − 1 → k alone, k's disparity then
warped again from k − 1's, was tried: ``drive`` seeds 1-3 went to 24.5 / 12.9 /
24.7 cm, against 6.9 / 3.9 / 5.8 with this one and 9.9 / 3.2 / 17.4 without.)
"""

from __future__ import annotations

from droidw_cli.slam import graph
from droidw_cli.slam.optimizer import run_window


def place_keyframe(frontend, k: int, iters: int) -> None:
    """Move keyframe k's pose and disparity by ``iters`` BA iterations against keyframe k − 1 alone."""
    if iters <= 0 or k < 1:
        return
    fe = frontend
    pairs = graph.radius_pairs(k, k - 1, 1)
    fe._match(pairs, use_prior=True)
    held = fe.buffer.disps[k - 1].clone()
    iterations = fe.shared.iterations
    run_window(fe.backend, fe.buffer, k - 1, k + 1, fe.cache.edge_set(pairs, offset=k - 1), fe._fixed_focal,
               fe.shared, iters, fixed=1, optimize_theta=False, robust_sigma=fe.fcfg.robust_sigma)
    fe.buffer.disps[k - 1] = held
    fe.shared.iterations = iterations
