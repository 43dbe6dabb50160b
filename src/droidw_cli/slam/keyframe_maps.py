"""Per-keyframe maps read off the frontend's state: evidence, mean edge confidence and the uncertainty u.

:class:`KeyframeMaps` is a base of :class:`~droidw_cli.slam.frontend.Frontend`; it reads its
``buffer``, ``cache``, ``shared``, ``params`` and ``backend``.  Archived keyframes (their images,
features and edges dropped) give their frozen maps.
"""

from __future__ import annotations

import numpy as np
import torch

from droidw_cli.ba.uncertainty import uncertainty_map
from droidw_cli.geometry.projection import reproject
from droidw_cli.slam.evidence import EVIDENCE_CHANNELS, evidence_maps
from droidw_cli.slam.optimizer import window_state

#: :meth:`KeyframeMaps.uncertainty` computes the evidence maps of this many keyframes at a time (all 200
#: of the backend's horizon at once reproject some 2000 edges, a few hundred MB at a run's end)
UNCERTAINTY_CHUNK = 32


class KeyframeMaps:
    """Evidence, confidence and u of keyframes [lo, hi), as the frontend's state gives them."""

    def in_view(self, i: int, js: list[int], targets: list[torch.Tensor] | None = None) -> list[np.ndarray]:
        """(h, w) bool per keyframe j of ``js``: the grid cells of keyframe i whose reprojection into j
        (Eq. 1, the current poses and disparities) lies in front of it and inside its view (cell centres
        span [−½, w − ½] × [−½, h − ½]), or, given ``targets`` (the measured (h, w, 2) target p*_ij per j),
        whose measured target lies inside it.  The reprojection is that of a static point: a mover's cell
        can leave the view by the map while its correspondence stays in it, and that correspondence is
        evidence of motion; a cell unseen by both was extrapolated by the flow and is no evidence."""
        buf = self.buffer
        n = len(buf)
        ii = torch.full((len(js),), i, dtype=torch.long, device=buf.device)
        jj = torch.tensor(js, dtype=torch.long, device=buf.device)
        coords, valid = reproject(buf.poses[:n], buf.disps[:n], self.shared.intrinsics, ii, jj, self.params.min_depth)
        inside = valid & _inside(coords, buf.grid)
        if targets is not None:
            inside |= _inside(torch.stack([t.to(coords) for t in targets]), buf.grid)
        return list(inside.cpu().numpy())

    def evidence(self, lo: int = 0, hi: int | None = None) -> torch.Tensor | None:
        """Evidence channels (hi − lo, C, h, w) of keyframes [lo, hi) from their cached outgoing edges
        (None when unused)."""
        unc = self.params.uncertainty
        n = len(self.buffer)
        hi = n if hi is None else hi
        if not (unc.enable and unc.evidence) or self.buffer.features is None:
            return None
        pairs = [p for p in self.cache.pairs() if lo <= p[0] < hi]
        if n < 2 or not pairs:
            return torch.zeros(hi - lo, EVIDENCE_CHANNELS, *self.buffer.grid, device=self.buffer.device)
        start = min(lo, min(j for _, j in pairs))
        state = window_state(self.buffer, start, n, self.shared, with_features=False)
        maps = evidence_maps(self.backend, state, self.cache.edge_set(pairs, offset=start), self.params.min_depth)
        return maps[lo - start:hi - start]

    def confidence(self, lo: int = 0, hi: int | None = None) -> torch.Tensor:
        """Mean confidence (hi − lo, h, w) of each keyframe's cached outgoing edges (archived: frozen)."""
        buf = self.buffer
        hi = len(buf) if hi is None else hi
        conf = torch.zeros(hi - lo, *buf.grid, device=buf.device)
        count = torch.zeros(hi - lo)
        for i, j in self.cache.pairs():
            if lo <= i < hi:
                conf[i - lo] += self.cache.weight((i, j))[..., 0].float()
                count[i - lo] += 1
        conf /= count.clamp(min=1).to(conf.device)[:, None, None]
        for k, c in buf.frozen_conf.items():
            if lo <= k < hi:
                conf[k - lo] = c.float()
        return conf

    def uncertainty(self, lo: int = 0, hi: int | None = None) -> torch.Tensor | None:
        """u (hi − lo, h, w) of keyframes [lo, hi) under the current θ (archived: frozen); None when off."""
        buf, theta = self.buffer, self.shared.theta
        hi = len(buf) if hi is None else hi
        if buf.features is None or theta is None or not self.params.uncertainty.enable:
            return None
        live = [k for k in range(lo, hi) if k not in buf.frozen_u]
        out = torch.zeros(hi - lo, *buf.grid, device=buf.device)
        if live:
            a, b = live[0], live[-1] + 1  # archived keyframes are the oldest: the live ones are contiguous
            # evidence in chunks of keyframes (a frame's maps read only its own edges: the same values), the
            # affine map over the whole range at once (its matrix product rounds differently per batch size)
            chunks = [self.evidence(c, min(b, c + UNCERTAINTY_CHUNK)) for c in range(a, b, UNCERTAINTY_CHUNK)]
            maps = None if chunks[0] is None else torch.cat(chunks)
            out[a - lo:b - lo] = uncertainty_map(buf.feature_block(a, b, torch.float32), theta,
                                                 self.params.uncertainty.softplus_offset, maps)
        for k, u in buf.frozen_u.items():
            if lo <= k < hi:
                out[k - lo] = u.float()
        return out


def _inside(coords: torch.Tensor, grid: tuple[int, int]) -> torch.Tensor:
    """(..., h, w) bool: grid coordinates (..., h, w, 2) inside the view [−½, w − ½] × [−½, h − ½]."""
    h, w = grid
    x, y = coords[..., 0], coords[..., 1]
    return (x >= -0.5) & (x <= w - 0.5) & (y >= -0.5) & (y <= h - 0.5)
