"""The data term γ_data·E_sim of the uncertainty objective and its ∂/∂u map, in torch.

See :mod:`droidw_cli.ba.uncertainty` for the objective.  Per E_sim edge k and
pixel p of frame i, with bilinear corners q_c and weights w_c of p_ij in frame j
(border-clamped):

    F_ij = Σ_c w_c F_j[q_c],      cos = F_i·F_ij / max(‖F_i‖ ‖F_ij‖, ε),
    u_ij = Σ_c w_c u_j[q_c],      t = ω_k γ_data valid (1 − s) / (u_i u_ij)
    G[i, p] −= t / u_i,           G[j, q_c] −= w_c t / u_ij.

The features are read through a :class:`FeatureTable`: one channel-last float32
copy (N·HW, C) with the per-pixel norms ‖F‖, built once per features tensor and
reused while that tensor is unchanged (the tracker keeps one window's features
for all its iterations).  F_ij is one fused gather-and-blend per edge pixel
(``embedding_bag`` with the bilinear weights as per-sample weights, never four
separate (E, HW, C) gathers), and F_i·F_ij broadcasts F_i over the edges of
frame i instead of gathering it.  Edges go in chunks (memory bounded by
``chunk_bytes``), so nothing of size (E, HW, C) is held at once.
"""

from __future__ import annotations

import torch
import torch.nn.functional as tnf
from torch import Tensor

from droidw_cli.ba.uncertainty import COS_EPS, channel_dot, similarity_score
from droidw_cli.geometry.sampling import inside_image
from droidw_cli.geometry.projection import relative_poses
from droidw_backend_cpu.reproject import FrameGeometry, ProjectionCache, bilinear_rows, version

#: bytes of gathered features per chunk of edges (the blended F_ij stays under glibc's 32 MB
#: mmap ceiling, so its memory is reused between chunks instead of being mapped afresh)
DEFAULT_FEATURE_CHUNK_BYTES = 32 * 2**20
#: (HW, C) float32 tensors alive per edge of a chunk (the blended F_ij and the product with F_i)
_FEATURE_TEMPS = 2


class FeatureTable:
    """The features as float32 channels-last (N, C, H, W) and their norms (N, HW), cached for one tensor.

    Channels-last memory is the (N·HW, C) table the similarity term gathers rows
    from, and :func:`droidw_cli.ba.uncertainty.uncertainty_logits` /
    ``theta_gradient`` read it as one matrix-vector product.  Features that are
    float32 channels-last already are used as they are.  The cache is keyed on
    the tensor object itself (held, so its memory cannot be reused by another
    tensor), its version counter (bumped by every in-place write), shape, dtype
    and device; any change rebuilds it.
    """

    def __init__(self) -> None:
        self._key: tuple | None = None
        self._value: tuple[Tensor, Tensor] | None = None
        self._dot_key: tuple | None = None
        self._dot: Tensor | None = None

    def get(self, features: Tensor) -> tuple[Tensor, Tensor]:
        """(channels-last float32 features (N, C, H, W), norms ‖F‖ (N, HW) float32)."""
        key = (features, version(features), tuple(features.shape), features.dtype, features.device)
        if self._key is not None and self._key[0] is features and self._key[1:] == key[1:] and key[1] is not None:
            return self._value
        n, c, h, w = features.shape
        if features.dtype == torch.float32 and features.is_contiguous(memory_format=torch.channels_last):
            cl = features
        else:
            src = features.reshape(n, c, h * w)
            rows = torch.empty(n, h * w, c, dtype=torch.float32, device=features.device)
            direct = features.dtype == torch.float32 and features.is_contiguous()
            frame = None if direct else torch.empty(c, h * w, dtype=torch.float32, device=features.device)
            for f in range(n):  # one frame at a time: cache-sized, and torch's blocked 2-D transpose applies
                if direct:
                    rows[f].copy_(src[f].t())
                else:  # convert (and make contiguous) first: a converting transpose is several times slower
                    frame.copy_(src[f])
                    rows[f].copy_(frame.t())
            cl = rows.view(n, h, w, c).permute(0, 3, 1, 2)
        norms = torch.linalg.vector_norm(rows_of(cl), dim=1).reshape(n, h * w)
        self._key, self._value = key, (cl, norms)
        return self._value

    def logits(self, features: Tensor, theta: Tensor, map_inputs: Tensor | None = None) -> Tensor:
        """a = θ[:C]·F + θ[C:-1]·X + θ[-1] (N, H, W), as :func:`droidw_cli.ba.uncertainty.uncertainty_logits`.

        θ[:C]·F, one pass over all the features, is kept for the last θ[:C]: in
        the tracker the GN step and the next uncertainty step use the same θ.
        """
        cl, _ = self.get(features)
        n, c, h, w = cl.shape
        theta = theta.to(device=cl.device, dtype=torch.float32)
        key, stamp = self._dot_key, version(cl)
        same = key is not None and key[0] is cl and stamp is not None and key[1] == stamp
        if same and torch.equal(key[2], theta[:c]):
            a = self._dot
        else:
            a = channel_dot(cl, theta[:c])
            self._dot_key, self._dot = (cl, stamp, theta[:c].clone()), a
        if map_inputs is not None:
            a = a + channel_dot(map_inputs, theta[c:-1])
        return (a + theta[-1]).reshape(n, h, w)

    def clear(self) -> None:
        self._key = self._value = None
        self._dot_key = self._dot = None


def rows_of(cl: Tensor) -> Tensor:
    """The (N·HW, C) row view of channels-last features (N, C, H, W)."""
    n, c, h, w = cl.shape
    return cl.permute(0, 2, 3, 1).reshape(n * h * w, c)


def _frame_runs(ii: Tensor) -> list[tuple[int, int, int]]:
    """(frame, start, stop) of the runs of equal consecutive values of ii."""
    frames, counts = torch.unique_consecutive(ii, return_counts=True)
    runs, start = [], 0
    for f, cnt in zip(frames.tolist(), counts.tolist()):
        runs.append((int(f), start, start + int(cnt)))
        start += int(cnt)
    return runs


def similarity_data_term(poses: Tensor, disps: Tensor, intrinsics: Tensor, ii: Tensor, jj: Tensor,
                         omega: Tensor, features: Tensor, u: Tensor, gamma_data: float, sim_threshold: float,
                         min_depth: float, chunk_bytes: int = DEFAULT_FEATURE_CHUNK_BYTES,
                         target: Tensor | None = None, geo_sigma: float = 0.0,
                         table: FeatureTable | None = None,
                         projections: ProjectionCache | None = None) -> tuple[Tensor, Tensor]:
    """(G (N, HW) = ∂(γ_data E_sim)/∂u, γ_data E_sim as a 0-d tensor) over the E_sim edges ii, jj.

    features (N, C, H, W) any float dtype; u (N, HW) float32; omega (K,) edge weights;
    target (K, H, W, 2) the correspondence targets of these edges, used by the
    geometric factor of s when ``geo_sigma`` > 0; ``table``, ``projections``: caches to reuse.
    """
    n, c, h, w = features.shape
    hw = h * w
    cl, fnorm = (table or FeatureTable()).get(features)
    flat = rows_of(cl)
    ucol = u.reshape(-1, 1).float()
    grad = torch.zeros(n * hw, dtype=torch.float32, device=u.device)
    loss = torch.zeros((), dtype=torch.float32, device=u.device)
    # edges sorted by frame i, so that F_i is broadcast over each run of edges
    order = torch.argsort(ii, stable=True)
    ii, jj, omega = ii[order], jj[order], omega[order]
    target = None if target is None or geo_sigma <= 0 else target.index_select(0, order)
    cache = projections or ProjectionCache(max_bytes=0)
    size = max(1, chunk_bytes // (_FEATURE_TEMPS * hw * c * 4))
    for s0 in range(0, ii.shape[0], size):
        ic, jc, om = ii[s0:s0 + size], jj[s0:s0 + size], omega[s0:s0 + size]
        ec = ic.shape[0]
        proj = cache.peek(poses, disps, intrinsics, ic, jc, min_depth)
        proj = proj[0] if proj is not None else FrameGeometry(poses, disps, intrinsics, min_depth).project(
            ic, *relative_poses(poses, ic, jc))
        coords = proj.coords.float()
        x, y = coords[:, 0], coords[:, 1]
        valid = proj.valid & inside_image(x, y, h, w)
        idx, wts = bilinear_rows(x, y, h, w)  # (ec, HW, 4)
        idx += (jc * hw).view(-1, 1, 1)  # flat into (N·HW)
        idx, wts = idx.view(-1, 4), wts.view(-1, 4)
        fij = tnf.embedding_bag(idx, flat, per_sample_weights=wts, mode="sum").view(ec, hw, c)
        uij = tnf.embedding_bag(idx, ucol, per_sample_weights=wts, mode="sum").view(ec, hw)
        nij = torch.linalg.vector_norm(fij, dim=2)
        dot = torch.empty(ec, hw, dtype=torch.float32, device=u.device)
        for frame, a, b in _frame_runs(ic):
            torch.sum(fij[a:b].mul_(flat[frame * hw:(frame + 1) * hw]), dim=2, out=dot[a:b])
        cos = dot.div_((nij.mul_(fnorm.index_select(0, ic))).clamp_min_(COS_EPS))
        residual = None
        if target is not None:
            tc = target[s0:s0 + size].reshape(-1, hw, 2)
            residual = torch.hypot(tc[..., 0] - x, tc[..., 1] - y)
        sim = similarity_score(cos, sim_threshold, residual, geo_sigma)
        ui = u.index_select(0, ic)
        t = (1.0 - sim).mul_(valid).mul_((gamma_data * om).unsqueeze(1)).div_(ui * uij)
        loss += t.sum()
        grad.view(n, hw).index_add_(0, ic, -t / ui)
        grad.index_add_(0, idx.view(-1), wts.mul_((-t / uij).view(-1, 1)).view(-1))
    return grad.reshape(n, hw), loss
