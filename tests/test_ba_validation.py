"""Bad BA input is refused with a clear message (CPU backend)."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.synthetic import make_problem
from droidw_cli.ba.types import EdgeSet
from droidw_backend_cpu import CpuBackend


@pytest.fixture(scope="module")
def problem():
    return make_problem(4, h=8, w=10, radius=1, channels=4)


def _edges(e: EdgeSet, **changes) -> EdgeSet:
    d = {"ii": e.ii, "jj": e.jj, "target": e.target, "weight": e.weight}
    d.update(changes)
    return EdgeSet(**d)


@pytest.mark.parametrize("method", ["ba_step", "uncertainty_step"])
def test_empty_edges(problem, method):
    e = problem.edges
    empty = EdgeSet(e.ii[:0], e.jj[:0], e.target[:0], e.weight[:0])
    with pytest.raises(ValueError, match="edge set is empty"):
        getattr(CpuBackend(), method)(problem.truth, empty, BAParams())


def test_nan_targets(problem):
    target = problem.edges.target.clone()
    target[0, 1, 2, 0] = float("nan")
    with pytest.raises(ValueError, match="target contains NaN"):
        CpuBackend().ba_step(problem.truth, _edges(problem.edges, target=target), BAParams())


def test_index_out_of_range(problem):
    jj = problem.edges.jj.clone()
    jj[0] = 4
    with pytest.raises(ValueError, match=r"out of range: indices span \[0, 4\] but there are 4 frames"):
        CpuBackend().ba_step(problem.truth, _edges(problem.edges, jj=jj), BAParams())
    with pytest.raises(ValueError, match="out of range"):
        CpuBackend().reproject(problem.truth, problem.edges.ii, jj)


def test_self_edge(problem):
    with pytest.raises(ValueError, match="itself"):
        CpuBackend().ba_step(problem.truth, _edges(problem.edges, jj=problem.edges.ii.clone()), BAParams())


@pytest.mark.parametrize("field,bad,match", [
    ("target", lambda t: t[:, :, :-1], "target must have shape"),
    ("weight", lambda t: t[..., :1], "weight must have shape"),
    ("ii", lambda t: t[:-1], "ii and jj must both have shape"),
])
def test_mismatched_edge_shapes(problem, field, bad, match):
    e = problem.edges
    with pytest.raises(ValueError, match=match):
        CpuBackend().ba_step(problem.truth, _edges(e, **{field: bad(getattr(e, field))}), BAParams())


@pytest.mark.parametrize("field,bad,match", [
    ("disps", lambda s: s.disps[:-1], "disps must have shape"),
    ("poses", lambda s: s.poses[:, :6], "poses must have shape"),
    ("intrinsics", lambda s: s.intrinsics[:3], "intrinsics must have shape"),
    ("features", lambda s: s.features[:, :, :-1], "features must have shape"),
    ("theta", lambda s: s.theta[:-1], "theta must have shape"),
    ("depth_prior", lambda s: s.disps[:, :-1], "depth_prior must match"),
    ("frame_ids", lambda s: torch.arange(3), "frame_ids must have shape"),
])
def test_mismatched_state_shapes(problem, field, bad, match):
    state = problem.truth.with_(**{field: bad(problem.truth)})
    with pytest.raises(ValueError, match=match):
        CpuBackend().ba_step(state, problem.edges, BAParams())


def test_negative_weight_and_float_indices(problem):
    w = problem.edges.weight.clone()
    w[0, 0, 0, 0] = -1
    with pytest.raises(ValueError, match="weight must be >= 0"):
        CpuBackend().ba_step(problem.truth, _edges(problem.edges, weight=w), BAParams())
    with pytest.raises(ValueError, match="integer"):
        CpuBackend().ba_step(problem.truth, _edges(problem.edges, ii=problem.edges.ii.float()), BAParams())


def test_uncertainty_step_needs_features(problem):
    with pytest.raises(ValueError, match="features"):
        CpuBackend().uncertainty_step(problem.truth.with_(features=None), problem.edges, BAParams())


def test_bad_params_are_refused():
    with pytest.raises(ValueError, match="optimize_focal"):
        BAParams(optimize_focal="z")
    with pytest.raises(ValueError, match="mode"):
        UncertaintyParams(mode="sigmoid")
    with pytest.raises(ValueError, match="min_disp"):
        BAParams(min_disp=0.0)


def test_outputs_have_documented_shapes_and_dtypes(problem):
    backend = CpuBackend()
    state = problem.truth.with_(poses=problem.truth.poses.double())  # float64 input is accepted and cast
    res = backend.ba_step(state, problem.edges, BAParams())
    assert res.state.poses.dtype == torch.float32 and res.state.poses.shape == (4, 7)
    assert res.state.disps.shape == (4, 8, 10) and res.state.disps.dtype == torch.float32
    assert isinstance(res.cost, float) and res.solved
    coords, valid = backend.reproject(state, problem.edges.ii, problem.edges.jj)
    assert coords.shape == (problem.edges.num_edges, 8, 10, 2) and coords.dtype == torch.float32
    assert valid.shape == (problem.edges.num_edges, 8, 10) and valid.dtype == torch.bool
    unc = backend.uncertainty_step(problem.truth, problem.edges, BAParams(uncertainty=UncertaintyParams(min_frame_gap=1)))
    assert unc.theta.shape == (5,) and unc.theta.dtype == torch.float32 and isinstance(unc.loss, float)
