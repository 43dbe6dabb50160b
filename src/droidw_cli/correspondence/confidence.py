"""Per-pixel confidence of a dense flow: forward-backward consistency,
photometric agreement and staying inside the image.

With f = f_ij (i → j) and b = f_ji (j → i), for pixel x of frame i:

* forward-backward error   e_fb(x) = ‖f(x) + b(x + f(x))‖,
  weight  w_fb = exp(−(e_fb / τ_fb)²);
* photometric error        e_ph(x) = |I_i(x) − I_j(x + f(x))|  (gray in [0, 1]),
  weight  w_ph = exp(−(e_ph / σ_ph)²);
* inside                   x + f(x) ∈ [−½, W − ½] × [−½, H − ½]  (else weight 0);
* away from the border     x and x + f(x) at least m px (``margin``) inside the image
  (else weight 0).

w = w_fb · w_ph · inside · away.

The margin is there for DIS: its flow is biased towards the interior's
within a patch-and-smoothing radius of the image border (patches there
are clamped to the image and the variational refinement extrapolates).
Measured against the ground-truth flow on the ``walk`` preset (keyframe
pairs, 384 × 512, MEDIUM), the translational part of the flow on the
outermost 1/8-grid cell ring is 1.3 % short, 0.5 % on the next, 0.3 % and
0.1 % on the two after; a motion-only BA over the keyframe pairs with the
sensor depth fixed then finds translations 3.5 % short (0.985 without the
outer three rings), which an RGB-D reconstruction, whose depth fixes the
scale, keeps as a scale error (monocular Sim(3) absorbs part of it).  Sampling at x + f(x) is bilinear (``cv2.remap``).
"""

from __future__ import annotations

import cv2
import numpy as np

from droidw_cli.correspondence.grid import cached_grid


Maps = np.ndarray  # (H, W, 2) float32 sampling positions x + f(x), a CV_32FC2 map for ``cv2.remap``


def flow_map(flow: np.ndarray) -> Maps:
    """The sampling positions x + f(x), (H, W, 2) float32."""
    h, w = flow.shape[:2]
    return np.add(cached_grid(h, w), flow, dtype=np.float32)


def remap(field: np.ndarray, maps: Maps) -> np.ndarray:
    """field sampled bilinearly at ``maps`` (edges replicated); field (H, W) or (H, W, C) float32."""
    return cv2.remap(field, maps, None, interpolation=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def sample_at_flow(field: np.ndarray, flow: np.ndarray) -> np.ndarray:
    """field(x + flow(x)), bilinear, edges replicated.  field: (H, W) or (H, W, C) float32."""
    return remap(field, flow_map(flow))


def inside_mask(flow: np.ndarray, maps: Maps | None = None, margin: float = 0.0) -> np.ndarray:
    """(H, W) bool: x + flow(x) lies inside the image shrunk by ``margin`` px on every side
    (pixel-centre convention: the image spans [−½, W − ½] × [−½, H − ½])."""
    h, w = flow.shape[:2]
    pts = maps if maps is not None else flow_map(flow)
    mx, my = pts[..., 0], pts[..., 1]
    lo = np.float32(margin - 0.5)
    return (mx >= lo) & (mx <= w - 0.5 - margin) & (my >= lo) & (my <= h - 0.5 - margin)


def zero_border(weight: np.ndarray, margin: float) -> np.ndarray:
    """Zero (in place) the pixels of an (H, W) map whose centre lies within ``margin`` px of the
    image border (pixel x spans [x − ½, x + ½], so ⌈margin⌉ rows / columns on each side); returns it."""
    m = int(np.ceil(margin))
    if m > 0:
        weight[:m] = 0
        weight[-m:] = 0
        weight[:, :m] = 0
        weight[:, -m:] = 0
    return weight


def _fb_squared(flow_ij: np.ndarray, flow_ji: np.ndarray, maps: Maps) -> np.ndarray:
    d = flow_ij + remap(flow_ji, maps)
    return np.square(d[..., 0]) + np.square(d[..., 1])


def forward_backward_error(flow_ij: np.ndarray, flow_ji: np.ndarray, maps: Maps | None = None) -> np.ndarray:
    """(H, W) float32 ‖f_ij(x) + f_ji(x + f_ij(x))‖ in px."""
    return np.sqrt(_fb_squared(flow_ij, flow_ji, maps if maps is not None else flow_map(flow_ij)))


def photometric_error(gray_i: np.ndarray, gray_j: np.ndarray, flow_ij: np.ndarray, maps: Maps | None = None) -> np.ndarray:
    """(H, W) float32 |I_i(x) − I_j(x + f(x))| with uint8 gray images scaled to [0, 1]."""
    gj = remap(gray_j.astype(np.float32), maps if maps is not None else flow_map(flow_ij))
    return np.abs(gray_i.astype(np.float32) - gj) * np.float32(1.0 / 255.0)


def invert_flow(flow: np.ndarray, iters: int = 3) -> np.ndarray:
    """Approximate inverse b of a flow f (b(y) = −f(y + b(y))) by fixed-point iteration from b = −f.

    Used to start the backward flow from the same prior as the forward one.
    Exact for constant flows; good for smooth ones.
    """
    back = -flow
    for _ in range(iters):
        back = -sample_at_flow(flow, back)
    return np.ascontiguousarray(back, dtype=np.float32)


def flow_confidence(
    gray_i: np.ndarray,
    gray_j: np.ndarray,
    flow_ij: np.ndarray,
    flow_ji: np.ndarray,
    fb_thresh: float,
    photo_sigma: float,
    margin: float = 0.0,
) -> np.ndarray:
    """(H, W) float32 per-pixel confidence in [0, 1] (module docstring); ``margin`` in px."""
    maps = flow_map(flow_ij)
    z = _fb_squared(flow_ij, flow_ji, maps) * np.float32(1.0 / fb_thresh**2)
    z += np.square(photometric_error(gray_i, gray_j, flow_ij, maps) * np.float32(1.0 / photo_sigma))
    w = np.exp(-z)
    w[~inside_mask(flow_ij, maps, margin)] = 0.0
    if margin > 0:
        zero_border(w, margin)
    return w.astype(np.float32, copy=False)
