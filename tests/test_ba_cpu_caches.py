"""The CPU backend's reuse of work between calls: projections and channels-last features.

Reuse must never change a result: every cached path is compared with a fresh
backend (or a fresh computation), including after in-place changes of the inputs.
"""

from __future__ import annotations

import pytest
import torch

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.synthetic import make_problem, perturb
from droidw_cli.geometry.projection import reproject
from droidw_cli.slam.evidence import evidence_maps
from droidw_backend_cpu import CpuBackend
from droidw_backend_cpu.reproject import FrameGeometry, ProjectionCache
from droidw_backend_cpu.uncertainty import FeatureTable

pytestmark = pytest.mark.usefixtures("one_torch_thread")

TRACKER = BAParams(uncertainty=UncertaintyParams(mode="relative", bidirectional=True, geo_sigma=1.0, evidence=True))


@pytest.fixture(scope="module")
def problem():
    prob = make_problem(7, h=12, w=16, radius=2, movers=True, channels=8, seed=4)
    g = torch.Generator().manual_seed(6)
    state = perturb(prob.truth, trans=0.02, rot_deg=2.0, disp_rel=0.1, seed=5)
    return state.with_(theta=0.3 * torch.randn(9, generator=g)), prob.edges


def _fresh_projection(state, ii, jj):
    geo = FrameGeometry(state.poses, state.disps, state.intrinsics, 0.05)
    return geo.project(ii, *geo.relative(ii, jj))


def test_frame_geometry_matches_reference_projection(problem):
    state, edges = problem
    proj = _fresh_projection(state, edges.ii, edges.jj)
    coords, valid = reproject(state.poses, state.disps, state.intrinsics, edges.ii, edges.jj, 0.05)
    e = edges.num_edges
    assert torch.allclose(proj.coords.permute(0, 2, 1).reshape(coords.shape), coords, atol=1e-5)
    assert torch.equal(proj.valid.reshape(e, *valid.shape[1:]), valid)


def test_projection_cache_serves_subsets_and_notices_changes(problem):
    state, edges = problem
    cache = ProjectionCache()
    st = state.with_(poses=state.poses.clone(), disps=state.disps.clone())
    full, _, _ = cache.get(st.poses, st.disps, st.intrinsics, edges.ii, edges.jj, 0.05)
    again, _, _ = cache.get(st.poses, st.disps, st.intrinsics, edges.ii, edges.jj, 0.05)
    assert again.coords is full.coords  # the same edges: the stored tensors as they are
    sub_ii, sub_jj = edges.ii.flip(0)[::2].clone(), edges.jj.flip(0)[::2].clone()
    hit = cache.peek(st.poses, st.disps, st.intrinsics, sub_ii, sub_jj, 0.05)
    ref = _fresh_projection(st, sub_ii, sub_jj)
    assert hit is not None
    for name in ("xy", "coords", "z", "disp", "valid"):
        assert torch.equal(getattr(hit[0], name), getattr(ref, name))
    assert cache.peek(st.poses, st.disps, st.intrinsics, torch.tensor([0]), torch.tensor([6]), 0.05) is None
    assert cache.peek(st.poses, st.disps, st.intrinsics, edges.ii, edges.jj, 0.1) is None
    st.disps.mul_(1.1)  # in-place: the version counter moves, the entry is stale
    assert cache.peek(st.poses, st.disps, st.intrinsics, edges.ii, edges.jj, 0.05) is None
    fresh, _, _ = cache.get(st.poses, st.disps, st.intrinsics, edges.ii, edges.jj, 0.05)
    fresh.coords.add_(1.0)  # a caller writing into a handed-out result invalidates it too
    assert cache.peek(st.poses, st.disps, st.intrinsics, edges.ii, edges.jj, 0.05) is None
    assert cache.peek(st.poses.clone(), st.disps, st.intrinsics, edges.ii, edges.jj, 0.05) is None


def test_window_iteration_with_reuse_equals_fresh_backends(problem):
    """evidence → uncertainty step → GN step on one backend (reusing) vs a new backend per call."""
    state, edges = problem
    n, _, h, w = state.features.shape
    state = state.with_(theta=torch.cat((state.theta[:-1], torch.tensor([0.2, -0.1]), state.theta[-1:])))
    shared = CpuBackend()
    ev = evidence_maps(shared, state, edges, TRACKER.min_depth)
    ev_ref = evidence_maps(CpuBackend(), state, edges, TRACKER.min_depth)
    assert torch.equal(ev, ev_ref)
    st = state.with_(map_inputs=ev)
    theta = shared.uncertainty_step(st, edges, TRACKER).theta
    theta_ref = CpuBackend().uncertainty_step(st, edges, TRACKER).theta
    assert torch.equal(theta, theta_ref)
    st = st.with_(theta=theta)
    res = shared.ba_step(st, edges, TRACKER)
    ref = CpuBackend().ba_step(st, edges, TRACKER)
    assert torch.equal(res.state.poses, ref.state.poses) and torch.equal(res.state.disps, ref.state.disps)
    assert res.cost == ref.cost
    # the next iteration sees the new state: nothing stale may be reused
    res2 = shared.ba_step(res.state, edges, TRACKER)
    ref2 = CpuBackend().ba_step(res.state, edges, TRACKER)
    assert torch.equal(res2.state.disps, ref2.state.disps)


def test_feature_table_layouts_and_invalidation(problem):
    state, _ = problem
    feats = state.features.contiguous(memory_format=torch.contiguous_format).clone()  # channels-first
    table = FeatureTable()
    cl, norms = table.get(feats)
    assert cl.is_contiguous(memory_format=torch.channels_last) and torch.equal(cl, feats)
    assert torch.allclose(norms, feats.norm(dim=1).reshape(norms.shape))
    assert table.get(feats)[0] is cl
    feats[0].mul_(2.0)
    cl2, _ = table.get(feats)
    assert cl2 is not cl and torch.equal(cl2, feats)
    half = feats.half()
    assert torch.equal(table.get(half)[0], half.float())
    already = feats.contiguous(memory_format=torch.channels_last)
    assert table.get(already)[0] is already


def test_uncertainty_step_same_for_either_feature_layout(problem):
    state, edges = problem
    params = BAParams(uncertainty=UncertaintyParams(geo_sigma=0.7))
    cf = state.features.contiguous(memory_format=torch.contiguous_format)
    cl = state.features.contiguous(memory_format=torch.channels_last)
    a = CpuBackend().uncertainty_step(state.with_(features=cf), edges, params)
    b = CpuBackend().uncertainty_step(state.with_(features=cl), edges, params)
    assert torch.allclose(a.theta, b.theta, rtol=1e-6, atol=1e-7) and a.loss == pytest.approx(b.loss, rel=1e-6)


def test_evidence_maps_match_their_definition(problem):
    """Mean wide-edge relative flow residual ρ = r / (1 + predicted flow) (log1p) and one minus the mean
    confidence, per frame and pixel."""
    state, edges = problem
    n, _, h, w = state.features.shape
    ev = evidence_maps(CpuBackend(), state, edges, 0.05)
    coords, valid = reproject(state.poses.double(), state.disps.double(), state.intrinsics.double(),
                              edges.ii, edges.jj, 0.05)
    for f in range(n):
        out = (edges.ii == f).nonzero().squeeze(1)
        if not len(out):
            assert torch.equal(ev[f], torch.zeros(2, h, w))
            continue
        wide = out[(edges.ii[out] - edges.jj[out]).abs() >= 2]
        v = valid[wide].double()
        grid = torch.stack(torch.meshgrid(torch.arange(w, dtype=torch.float64), torch.arange(h, dtype=torch.float64),
                                          indexing="xy"), -1)
        predicted = (coords[wide] - grid).norm(dim=-1)
        r = (edges.target[wide].double() - coords[wide]).norm(dim=-1) / (1.0 + predicted) * v
        residual = torch.log1p(r.sum(0) / v.sum(0).clamp_min(1.0))
        doubt = 1.0 - edges.weight[out][..., 0].double().mean(0)
        assert torch.allclose(ev[f, 0].double(), residual, atol=1e-5)
        assert torch.allclose(ev[f, 1].double(), doubt, atol=1e-6)


def test_sampling_helpers_match_the_reference_sampler():
    from droidw_cli.geometry.sampling import bilinear_corners, sample_maps
    from droidw_backend_cpu.reproject import bilinear_rows, sample_scalar

    g = torch.Generator().manual_seed(0)
    n, h, w = 4, 6, 9
    maps = torch.rand(n, h, w, generator=g)
    frames = torch.tensor([3, 0, 2])
    x = torch.rand(3, 50, generator=g) * (w + 2) - 1
    y = torch.rand(3, 50, generator=g) * (h + 2) - 1
    x[0, :4] = torch.tensor([0.0, w - 1.0, -0.5, w - 1.5])
    y[0, :4] = torch.tensor([h - 1.0, 0.0, h + 3.0, h - 1.0])
    ref = sample_maps(maps, frames, x, y)
    assert torch.allclose(sample_scalar(maps, frames, x, y), ref, atol=1e-6)
    idx, wts = bilinear_rows(x, y, h, w)
    idx0, wts0 = bilinear_corners(x, y, h, w, dim=-1)
    assert torch.equal(idx, idx0) and torch.equal(wts, wts0)


def test_edge_values_are_checked_again_after_an_in_place_change(problem):
    state, edges = problem
    backend = CpuBackend()
    target = edges.target.clone()
    mine = type(edges)(edges.ii, edges.jj, target, edges.weight)
    backend.ba_step(state, mine, BAParams())
    backend.ba_step(state, mine, BAParams())  # the same edges: their values are not checked twice
    target[0, 1, 2, 0] = float("nan")
    with pytest.raises(ValueError, match="target contains NaN"):
        backend.ba_step(state, mine, BAParams())
    with pytest.raises(ValueError, match="weight must be >= 0"):
        backend.uncertainty_step(state, type(edges)(edges.ii, edges.jj, edges.target, -edges.weight), BAParams())


def test_inference_mode_tensors_work_without_reuse(problem):
    """Tensors made in inference mode keep no version counter: nothing is reused, results are unchanged."""
    state, edges = problem
    ref = CpuBackend().ba_step(state, edges, TRACKER.__class__())
    with torch.inference_mode():
        st = state.with_(**{k: v.clone() for k, v in state.__dict__.items() if isinstance(v, torch.Tensor)})
        ed = type(edges)(edges.ii.clone(), edges.jj.clone(), edges.target.clone(), edges.weight.clone())
    backend = CpuBackend()
    backend.reproject(st, ed.ii, ed.jj)
    backend.uncertainty_step(st, ed, BAParams())
    res = backend.ba_step(st, ed, BAParams())
    assert torch.equal(res.state.poses, ref.state.poses) and torch.equal(res.state.disps, ref.state.disps)


def test_release_drops_the_caches_and_changes_no_result(problem):
    state, edges = problem
    backend = CpuBackend()
    backend.uncertainty_step(state, edges, TRACKER)
    first = backend.ba_step(state, edges, TRACKER)
    assert backend._features._value is not None and backend._projections._entry is not None
    backend.release()
    assert backend._features._value is None and backend._projections._entry is None
    again = backend.ba_step(state, edges, TRACKER)
    assert torch.equal(again.state.poses, first.state.poses) and again.cost == first.cost
