"""The Cauchy reweighting of BA edges (:func:`droidw_cli.slam.optimizer.robust_edges`)."""

from __future__ import annotations

import torch

from droidw_cli.ba.registry import get_backend
from droidw_cli.ba.types import BAState, EdgeSet


def _state(h: int = 6, w: int = 8) -> BAState:
    poses = torch.tensor([[0.0, 0, 0, 0, 0, 0, 1], [0.1, 0, 0, 0, 0, 0, 1]])
    return BAState(poses=poses, disps=torch.full((2, h, w), 0.5), intrinsics=torch.tensor([10.0, 10.0, 4.0, 3.0]))


def test_robust_edges_cauchy_weight():
    from droidw_cli.slam.optimizer import robust_edges

    backend = get_backend("cpu")
    state = _state()
    ii, jj = torch.tensor([0]), torch.tensor([1])
    coords, _ = backend.reproject(state, ii, jj)
    offset = torch.zeros_like(coords)
    offset[0, :, :4, 0] = 2.0  # left half: 2 grid px off the rigid prediction, right half exact
    edges = EdgeSet(ii, jj, coords + offset, torch.full((*coords.shape[:3], 2), 0.5))
    out = robust_edges(backend, state, edges, sigma=1.0, min_depth=0.05)
    assert torch.allclose(out.weight[0, :, :4], torch.full_like(out.weight[0, :, :4], 0.5 / 5.0))  # 1/(1 + 4)
    assert torch.allclose(out.weight[0, :, 4:], torch.full_like(out.weight[0, :, 4:], 0.5))
    assert out.target is edges.target and out.ii is ii


class _CountingBackend:
    """A backend that counts its reprojections and passes everything else through."""

    def __init__(self, inner):
        self.inner, self.reprojections = inner, 0

    def reproject(self, *args, **kwargs):
        self.reprojections += 1
        return self.inner.reproject(*args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def test_run_window_reprojects_once_per_iteration():
    """The evidence maps and the Cauchy weights share one reprojection per iteration (θ's step moves no pose),
    and reading them from it gives the same window as reprojecting for each."""
    import numpy as np

    from droidw_cli.ba.params import BAParams, UncertaintyParams
    from droidw_cli.ba.synthetic import make_problem, perturb
    from droidw_cli.slam import optimizer
    from droidw_cli.slam.keyframes import KeyframeBuffer

    prob = make_problem(5, h=12, w=16, radius=2, channels=8, seed=0)
    start = perturb(prob.truth, fixed=1, seed=1)
    n, c, h, w = start.features.shape
    params = BAParams(uncertainty=UncertaintyParams(mode="relative", bidirectional=True, evidence=True))

    def window(backend):
        buf = KeyframeBuffer((h, w), feature_channels=c)
        for t in range(n):
            buf.append(t, float(t), start.poses[t], start.disps[t], np.zeros((h, w, 3), np.uint8), start.features[t])
        shared = optimizer.SharedState(intrinsics=start.intrinsics.clone(), theta=torch.full((c + 3,), 0.01),
                                       iterations=100)
        optimizer.run_window(backend, buf, 0, n, prob.edges, params, shared, 3, 1, robust_sigma=1.0)
        return buf.poses[:n].clone(), buf.disps[:n].clone()

    counting = _CountingBackend(get_backend("cpu"))
    poses, disps = window(counting)
    assert counting.reprojections == 3  # one per iteration, not one for the evidence and one for the weights

    separate = _CountingBackend(get_backend("cpu"))
    real_evidence, real_robust = optimizer.evidence_maps, optimizer.robust_edges
    try:  # each user reprojecting for itself, as before
        optimizer.evidence_maps = lambda b, s, e, d, projection=None: real_evidence(b, s, e, d)
        optimizer.robust_edges = lambda b, s, e, sg, d, projection=None: real_robust(b, s, e, sg, d)
        poses_sep, disps_sep = window(separate)
    finally:
        optimizer.evidence_maps, optimizer.robust_edges = real_evidence, real_robust
    assert separate.reprojections == 9
    assert torch.equal(poses, poses_sep) and torch.equal(disps, disps_sep)
