"""Where an edge's flow starts: the motion filter's flow, or the map's prediction.

DIS finds motions of a few tens of pixels on its own; a camera travelling
into the scene at 10 frames/s moves the near road and facades by far more
between keyframes, and DIS needs a start there (:func:`~droidw_cli.correspondence.dis.calc_warped`).
Each new edge (i, j) gets the first of these that exists:

1. **adjacent pairs**: the motion filter's flow between the two, when one was
   the other's reference (it was measured frame by frame, each frame started
   from the last: :mod:`droidw_cli.slam.motion_filter`), brought to the
   working size (:func:`adjacent_start`); none where the motion filter kept
   no flow (a motion DIS finds alone), as the scout matches them ahead
   (:mod:`droidw_cli.slam.scout`: the same bytes either way);
2. **wider pairs**: the flow the current poses and disparities induce (Eq. 1).

A start from the map carries the map's scale into the measurement (the
warped DIS keeps a few per cent of a start's error).  Starting wider pairs
instead from a chain of two matched edges, p*_ij(x) = p*_mj(p*_im(x)), which
knows nothing of the map, was tried and left out: on seeds 1-3 it moved ATE
(% of the path) of ``forward``/``ride``/``drive`` from 0.059/0.071/0.107 to
0.044/0.042/0.107 (links gated at confidence 0.2), within the seed-to-seed
spread, and doubled it on ``rotate`` (seeds 1 and 3: 0.77 → 1.42 cm and
0.50 → 0.82 cm).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch

from droidw_cli.correspondence.confidence import invert_flow


def adjacent_start(flow_half: np.ndarray, size: tuple[int, int], invert: bool) -> np.ndarray:
    """The motion filter's half-size flow a → b (:attr:`~droidw_cli.slam.motion_filter.MotionFilter.accepted_flow`)
    at the working size ``size`` (H, W), as the start of the flow a → b, or of b → a with ``invert``."""
    scale = np.float32(size[1] / flow_half.shape[1])
    full = cv2.resize(flow_half, (size[1], size[0]), interpolation=cv2.INTER_LINEAR) * scale
    return invert_flow(full) if invert else np.ascontiguousarray(full, dtype=np.float32)


def induced_start(flow_grid: torch.Tensor, valid: torch.Tensor, size: tuple[int, int]) -> np.ndarray:
    """The flow (h, w, 2) in grid px that the poses and disparities induce (zero where not ``valid``), at the
    working size ``size`` (H, W) in its pixels, as the start of an edge's flow."""
    f = torch.where(valid[..., None], flow_grid, torch.zeros_like(flow_grid)).numpy() * 8.0
    return cv2.resize(np.ascontiguousarray(f), (size[1], size[0]), interpolation=cv2.INTER_LINEAR)
