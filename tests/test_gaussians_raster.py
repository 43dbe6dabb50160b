"""The pure-torch rasteriser against a brute-force per-pixel loop, its gradients against finite differences,
and the choice of a rasteriser."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.errors import UserError
from droidw_cli.gaussians.camera import Camera
from droidw_cli.gaussians.model import Gaussians, dc_to_rgb
from droidw_cli.gaussians.raster import resolve_rasteriser
from droidw_cli.gaussians.torch_raster import ALPHA_MAX, ALPHA_MIN, TorchRasteriser, project

BG = (0.1, 0.2, 0.3)


def scene(n=7, seed=0, dtype=torch.float64) -> tuple[Gaussians, Camera]:
    gen = torch.Generator().manual_seed(seed)
    rnd = (lambda *s: torch.randn(*s, generator=gen, dtype=dtype))
    g = Gaussians(rnd(n, 3) * 0.3 + torch.tensor([0.0, 0.0, 3.0], dtype=dtype), rnd(n, 3) * 0.2 - 1.6, rnd(n, 4),
                  rnd(n), rnd(n, 3))
    g.means[-1, 2] = -1.0  # one behind the camera: culled
    rot = torch.linalg.matrix_exp(torch.tensor([[0, -0.1, 0.05], [0.1, 0, -0.02], [-0.05, 0.02, 0]], dtype=dtype))
    w2c = torch.eye(4, dtype=dtype)
    w2c[:3, :3], w2c[:3, 3] = rot, torch.tensor([0.05, -0.02, 0.1], dtype=dtype)
    return g, Camera((9.0, 8.5, 4.3, 3.1), w2c, (7, 10))


def brute_force(g: Gaussians, cam: Camera):
    """Every pixel, every Gaussian, front to back (the rules of torch_raster's docstring, as plain loops)."""
    mean2d, conic, z, radius = project(g, cam, 1e-3)
    opacity, rgb = torch.sigmoid(g.opacity_logits), dc_to_rgb(g.dc)
    h, w = cam.size
    colour = torch.zeros(h, w, 3, dtype=g.means.dtype)
    depth = torch.zeros(h, w, dtype=g.means.dtype)
    acc = torch.zeros(h, w, dtype=g.means.dtype)
    order = sorted(range(len(g)), key=lambda i: float(z[i]))
    for v in range(h):
        for u in range(w):
            trans = 1.0
            for i in order:
                dx, dy = u - mean2d[i, 0], v - mean2d[i, 1]
                if radius[i] == 0 or abs(dx) > radius[i] or abs(dy) > radius[i]:
                    continue
                power = -0.5 * (conic[i, 0] * dx * dx + conic[i, 2] * dy * dy) - conic[i, 1] * dx * dy
                a = opacity[i] * torch.exp(power)
                if a < ALPHA_MIN:
                    continue
                a = torch.clamp_max(a, ALPHA_MAX)
                colour[v, u] += rgb[i] * a * trans
                depth[v, u] += z[i] * a * trans
                acc[v, u] += a * trans
                trans = trans * (1 - a)
            colour[v, u] += (1 - acc[v, u]) * torch.tensor(BG, dtype=g.means.dtype)
    return colour, depth, acc


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_the_brute_force_loop(seed):
    g, cam = scene(seed=seed)
    out = TorchRasteriser().render(g, cam, BG)
    colour, depth, acc = brute_force(g, cam)
    assert out.pairs > 20 and float(acc.max()) > 0.5  # the case is not empty
    torch.testing.assert_close(out.colour, colour, atol=1e-12, rtol=0)
    torch.testing.assert_close(out.depth, depth, atol=1e-12, rtol=0)
    torch.testing.assert_close(out.alpha, acc, atol=1e-12, rtol=0)
    assert out.radius[-1] == 0  # behind the camera


def test_a_crop_renders_the_same_pixels():
    g, cam = scene(seed=4)
    full = TorchRasteriser().render(g, cam, BG).colour
    part = TorchRasteriser().render(g, cam.crop(2, 3, 4, 5), BG).colour
    torch.testing.assert_close(part, full[2:6, 3:8], atol=1e-12, rtol=0)


def test_gradients_match_finite_differences():
    g, cam = scene(n=4, seed=5)
    names = Gaussians.TRAINABLE
    inputs = tuple(getattr(g, n).clone().requires_grad_(True) for n in names)
    weights = torch.linspace(0.5, 1.5, 7 * 10 * 5, dtype=torch.float64).reshape(7, 10, 5)

    def f(*params):
        out = TorchRasteriser().render(Gaussians(*params), cam, BG)
        return (torch.cat([out.colour, out.depth[..., None], out.alpha[..., None]], -1) * weights).sum()

    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-4)


def test_empty_map_renders_the_background():
    _, cam = scene()
    out = TorchRasteriser().render(Gaussians.empty(torch.float64), cam, BG)
    assert torch.allclose(out.colour, torch.tensor(BG, dtype=torch.float64).expand(7, 10, 3))
    assert float(out.alpha.abs().max()) == 0


def test_auto_takes_torch_without_cuda_and_names_why():
    rast, how = resolve_rasteriser("auto")
    if not torch.cuda.is_available():
        assert rast.name == "torch" and "gsplat:" in how
    with pytest.raises(UserError, match="unknown rasteriser"):
        resolve_rasteriser("opengl")
    if not torch.cuda.is_available():
        with pytest.raises(UserError, match="cannot run here"):
            resolve_rasteriser("gsplat")
