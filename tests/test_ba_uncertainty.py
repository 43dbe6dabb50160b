"""The uncertainty model, its analytic gradient (vs autograd) and the movers robustness check."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as tf

from droidw_cli.ba.params import BAParams, UncertaintyParams
from droidw_cli.ba.synthetic import make_problem, max_pose_error, perturb
from droidw_cli.ba.types import BAState, EdgeSet
from droidw_cli.ba.uncertainty import RELATIVE_LEVEL, uncertainty_map, weight_factor, weighting_input
from droidw_cli.geometry.projection import reproject
from droidw_backend_cpu import CpuBackend

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _autograd_loss(state: BAState, edges: EdgeSet, theta: torch.Tensor, unc: UncertaintyParams) -> torch.Tensor:
    """E_uncer written independently (grid_sample, cosine_similarity) for autograd."""
    n, c, h, w = state.features.shape
    feats = state.features.double()
    inputs = feats if state.map_inputs is None else torch.cat((feats, state.map_inputs.double()), 1)
    a = torch.einsum("c,nchw->nhw", theta[:-1], inputs) + theta[-1]
    u = torch.log(unc.softplus_offset + torch.exp(a))
    ids = state.keyframe_ids()
    keep = (ids[edges.ii] - ids[edges.jj]).abs() >= unc.min_frame_gap
    ii, jj = edges.ii[keep], edges.jj[keep]
    coords, valid = reproject(state.poses.double(), state.disps.double(), state.intrinsics.double(), ii, jj)
    x, y = coords[..., 0], coords[..., 1]
    valid = valid & (x >= 0) & (x <= w - 1) & (y >= 0) & (y <= h - 1)
    grid = torch.stack((2 * x / (w - 1) - 1, 2 * y / (h - 1) - 1), -1)
    fij = tf.grid_sample(feats[jj], grid, align_corners=True, padding_mode="border")
    uij = tf.grid_sample(u[jj].unsqueeze(1), grid, align_corners=True, padding_mode="border")[:, 0]
    s = tf.cosine_similarity(feats[ii], fij, dim=1).clamp(0, 1)
    if unc.geo_sigma > 0:
        r = (edges.target[keep].double() - coords).norm(dim=-1)
        s = s * torch.exp(-(r / unc.geo_sigma) ** 2)
    s = torch.where(s < unc.sim_threshold, torch.zeros_like(s), s)
    e_k = (valid * (1 - s) / (u[ii] * uij)).sum((1, 2))
    counts = torch.bincount(torch.cat((ii, jj)), minlength=n).double()
    involved = counts > 0
    if unc.average_per_keyframe:
        per_frame = torch.zeros(n, dtype=torch.float64).index_add(0, ii, e_k).index_add(0, jj, e_k)
        data = (per_frame[involved] / counts[involved]).sum() / involved.sum()
    else:
        data = e_k.mean()
    prior = torch.log1p(u[involved]).sum() / involved.sum()
    return unc.gamma_data * data + unc.gamma_prior * prior


@pytest.fixture(scope="module")
def small_problem():
    prob = make_problem(6, h=12, w=16, radius=3, movers=True, mover_frames=(2, 3, 4, 5), channels=8, seed=3)
    state = perturb(prob.truth, trans=0.01, rot_deg=1.0, disp_rel=0.05, seed=4)
    g = torch.Generator().manual_seed(5)
    return state.with_(theta=0.5 * torch.randn(9, generator=g)), prob.edges


@pytest.mark.parametrize("per_keyframe", [True, False])
@pytest.mark.parametrize("frame_ids", [None, (0, 1, 3, 4, 6, 9)])
def test_uncertainty_gradient_matches_autograd(small_problem, per_keyframe, frame_ids):
    state, edges = small_problem
    if frame_ids is not None:
        state = state.with_(frame_ids=torch.tensor(frame_ids))
    unc = UncertaintyParams(average_per_keyframe=per_keyframe, lr=0.1, weight_decay=0.002)
    res = CpuBackend().uncertainty_step(state, edges, BAParams(uncertainty=unc))
    theta = state.theta.double().clone().requires_grad_(True)
    loss = _autograd_loss(state, edges, theta, unc)
    grad, = torch.autograd.grad(loss, theta)
    expect = state.theta.double() - unc.lr * grad - unc.weight_decay * state.theta.double()
    assert res.loss == pytest.approx(float(loss.detach()), rel=1e-4)
    assert torch.allclose(res.theta.double(), expect, rtol=1e-4, atol=1e-5)
    assert float(grad.abs().max()) > 1e-3  # the comparison is not trivially 0 = 0


@pytest.mark.parametrize("geo_sigma", [0.0, 0.7])
@pytest.mark.parametrize("with_inputs", [False, True])
def test_geometric_similarity_and_map_inputs_match_autograd(small_problem, geo_sigma, with_inputs):
    """droidw's extensions: the geometric factor of s and extra affine-map inputs X."""
    state, edges = small_problem
    n, _, h, w = state.features.shape
    if with_inputs:
        g = torch.Generator().manual_seed(11)
        state = state.with_(map_inputs=torch.rand(n, 2, h, w, generator=g),
                            theta=torch.cat((state.theta[:-1], torch.tensor([0.3, -0.2]), state.theta[-1:])))
    unc = UncertaintyParams(geo_sigma=geo_sigma, sim_threshold=0.2)
    res = CpuBackend().uncertainty_step(state, edges, BAParams(uncertainty=unc))
    theta = state.theta.double().clone().requires_grad_(True)
    loss = _autograd_loss(state, edges, theta, unc)
    grad, = torch.autograd.grad(loss, theta)
    expect = state.theta.double() - unc.lr * grad - unc.weight_decay * state.theta.double()
    assert res.loss == pytest.approx(float(loss.detach()), rel=1e-4)
    assert torch.allclose(res.theta.double(), expect, rtol=1e-4, atol=1e-5)
    if with_inputs:
        assert float(grad[-3:-1].abs().max()) > 1e-4  # the extra inputs get a real gradient


def test_no_similarity_edges_means_no_step(small_problem):
    state, edges = small_problem
    near = (edges.ii - edges.jj).abs() < 2
    sub = EdgeSet(edges.ii[near], edges.jj[near], edges.target[near], edges.weight[near])
    res = CpuBackend().uncertainty_step(state, sub, BAParams())
    assert res.loss == 0.0 and torch.equal(res.theta, state.theta)


def test_weight_factor_modes():
    u = torch.tensor([0.1, 0.8, 1.0, 2.0, 10.0])
    clamp = weight_factor(u, "clamp")
    assert torch.allclose(clamp, torch.tensor([1.0, 1.0, 0.1, 1 / 55.0, 1 / 415.0]))
    assert torch.allclose(weight_factor(u, "inverse"), 1 / u)
    with pytest.raises(ValueError):
        weight_factor(u, "bogus")


def test_uncertainty_map_offset_floor():
    feats = torch.zeros(1, 4, 2, 2)
    theta = torch.tensor([0, 0, 0, 0, -50.0])
    assert torch.allclose(uncertainty_map(feats, theta, 1.1), torch.full((1, 2, 2), torch.log(torch.tensor(1.1))))


def _auroc(score: torch.Tensor, label: torch.Tensor) -> float:
    s, lab = score.flatten().double(), label.flatten()
    ranks = torch.empty_like(s)
    ranks[torch.argsort(s)] = torch.arange(1, len(s) + 1, dtype=s.dtype)
    npos, nneg = int(lab.sum()), int((~lab).sum())
    return float((ranks[lab].sum() - npos * (npos + 1) / 2) / (npos * nneg))


def test_uncertainty_finds_movers_and_protects_the_poses():
    """30 % of the pixels of frames 4-9 move; u must find them and the weighted BA must win."""
    torch.manual_seed(0)
    prob = make_problem(10, radius=3, movers=True, mover_frames=tuple(range(4, 10)), channels=32,
                        mover_shift=(0.6, 0.3), seed=0)
    frac = float(prob.mover_mask[4:].float().mean())
    assert 0.25 < frac < 0.35
    backend = CpuBackend()
    start = perturb(prob.truth, trans=0.02, rot_deg=2.0, fixed=2, seed=1)
    plain = BAParams(t0=2, uncertainty=UncertaintyParams(enable=False))
    st = start
    for _ in range(10):
        st = backend.ba_step(st, prob.edges, plain).state
    err_plain = max_pose_error(st.poses, prob.truth.poses)[0]
    weighted = BAParams(t0=2)  # official γ's, λ and η
    st = start
    for _ in range(20):
        st = st.with_(theta=backend.uncertainty_step(st, prob.edges, weighted).theta)
        st = backend.ba_step(st, prob.edges, weighted).state
    for _ in range(3):
        st = backend.ba_step(st, prob.edges, weighted).state
    err_weighted = max_pose_error(st.poses, prob.truth.poses)[0]
    u = uncertainty_map(st.features, st.theta)
    assert _auroc(u[4:], prob.mover_mask[4:]) >= 0.95
    assert float(weight_factor(u[prob.mover_mask], "clamp").mean()) < 0.1
    assert float(weight_factor(u[~prob.mover_mask], "clamp").mean()) > 0.7
    print("movers:", err_weighted, err_plain, _auroc(u[4:], prob.mover_mask[4:]))
    assert 3.0 * err_weighted < err_plain, (err_weighted, err_plain)


def test_relative_mode_rescales_to_the_window_median():
    u = torch.tensor([[0.9, 1.0, 1.0, 1.1, 2.0]])
    rel = weighting_input(u, "relative")
    assert float(rel.median()) == pytest.approx(RELATIVE_LEVEL)
    w = weight_factor(rel, "relative")
    assert float(w[0, 1]) == 1.0 and float(w[0, 4]) < 0.1  # background untouched, the outlier cut
    assert torch.equal(weighting_input(u, "clamp"), u)
