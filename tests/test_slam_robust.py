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
