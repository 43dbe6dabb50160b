"""Region growing (MobileSAM substitute), components and inscribed-circle centres."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.dynamics import DetectionParams, grow_regions, inscribed_centres, label_components, refine_mask
from droidw_cli.dynamics.refine import surface_slant

H, W = 40, 50


def _scene(seed: int = 0):
    """Textured background at 3 m with a reddish textured square (rows 10-24, cols 15-31) at 1.5 m."""
    rng = np.random.default_rng(seed)
    img = 0.4 + 0.15 * rng.random((H, W, 3))
    depth = np.full((H, W), 3.0)
    sq = np.zeros((H, W), bool)
    sq[10:25, 15:32] = True
    img[sq] = np.array([0.85, 0.2, 0.15]) + 0.08 * rng.random((int(sq.sum()), 3))
    depth[sq] = 1.5 + 0.02 * rng.standard_normal(int(sq.sum()))
    return torch.tensor(img, dtype=torch.float32), torch.tensor(depth, dtype=torch.float32), sq


def test_growing_recovers_square_from_partial_seed():
    img, depth, sq = _scene()
    seed = torch.zeros(H, W, dtype=torch.bool)
    seed[12:16, 17:21] = True  # a 4×4 corner patch of the square
    objs = refine_mask(seed, img, depth, DetectionParams(grow_steps=30))
    got = objs.mask.numpy()
    assert objs.count == 1
    assert (got & sq).sum() / (got | sq).sum() >= 0.98
    assert not (got & ~sq).any()  # no leak into the background


def test_growing_is_limited_by_steps_and_similarity():
    img, depth, sq = _scene()
    seed = torch.zeros(H, W, dtype=torch.bool)
    seed[16:18, 22:24] = True
    lab = grow_regions(label_components(seed), img, depth, DetectionParams(grow_steps=2))
    assert int((lab > 0).sum()) == 4 + 8 + 12  # a 2×2 block grown twice by 4-neighbour dilation
    # a neighbour of the seed with the seed's colour but another depth is not taken
    depth2 = depth.clone()
    depth2[17, 24] = 2.5  # right of the seed; its left neighbour (17, 21) keeps depth ≈ 1.5
    lab = grow_regions(label_components(seed), img, depth2, DetectionParams(grow_steps=1))
    assert lab[17, 24] == 0 and lab[17, 21] == 1


def test_growing_leaks_nowhere_at_equal_depth_but_other_colour():
    img, _, sq = _scene()
    depth = torch.full((H, W), 2.0)  # depth gives no clue: colour alone must stop the growth
    seed = torch.zeros(H, W, dtype=torch.bool)
    seed[15:19, 20:24] = True
    got = refine_mask(seed, img, depth, DetectionParams(grow_steps=40)).mask.numpy()
    assert (got & sq).sum() / (got | sq).sum() >= 0.95 and not (got & ~sq).any()


def test_components_filter_and_centres():
    m = torch.zeros(30, 40, dtype=torch.bool)
    m[2:12, 3:13] = True  # 10×10 square
    m[28, 5] = True  # a single pixel, dropped by min_area
    m[18:27, 20:35] = True  # 9×15 rectangle
    lab = label_components(m, min_area=2)
    assert int(lab.max()) == 2 and lab[28, 5] == 0
    centres, radii = inscribed_centres(lab)
    x0, y0 = centres[0].tolist()
    assert 7 <= x0 <= 8 and 6 <= y0 <= 7  # middle of the 10×10 square
    x1, y1 = centres[1].tolist()
    assert y1 == 22 and 24 <= x1 <= 30 and radii[1] == pytest.approx(5.0, abs=0.1)


def test_centre_of_border_object_stays_inside():
    m = torch.zeros(20, 20, dtype=torch.bool)
    m[:, :6] = True  # touches three borders
    centres, _ = inscribed_centres(label_components(m))
    x, _ = centres[0].tolist()
    assert 2 <= x <= 3  # the image border counts as background


def test_params_reject_bad_values():
    for bad in ({"min_depth": 0.0}, {"depth_mode": "nearest"}, {"min_fraction": 0.0}, {"sign_margin": -1.0},
                {"grow_steps": -1}, {"max_growth": -1.0}, {"color_tol": -0.1}, {"max_slant": 0.0},
                {"max_slant": 95.0}, {"depth_step_tol": -0.1}):
        with pytest.raises(ValueError):
            DetectionParams(**bad)


def test_growth_cap_limits_area():
    img, depth, sq = _scene()
    seed = torch.zeros(H, W, dtype=torch.bool)
    seed[15:19, 20:24] = True
    objs = refine_mask(seed, img, depth, DetectionParams(grow_steps=40, max_growth=3.0))
    assert 48 <= int(objs.areas[0]) < 48 + 4 * 16  # stops within one step of 3 × 16 pixels


def _plane_depth(normal, c: float, focal: float, size=(H, W)) -> torch.Tensor:
    """Depth of the plane n·X = c along each pixel's ray (principal point at the image centre)."""
    h, w = size
    v, u = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    rays = torch.stack(((u - (w - 1) / 2) / focal, (v - (h - 1) / 2) / focal, torch.ones_like(u)), -1)
    return c / (rays @ torch.tensor(normal, dtype=torch.float64))


@pytest.mark.parametrize("degrees", [0.0, 30.0, 60.0])
def test_surface_slant_of_a_plane(degrees):
    """At the principal point, tan θ of a plane tilted by θ about the x axis is tan θ (to the one-pixel differences:
    D is not linear in v, and the smaller step is taken)."""
    f = 50.0
    t = np.radians(degrees)
    depth = _plane_depth((0.0, np.sin(t), np.cos(t)), 3.0 * np.cos(t), f, (41, 41))
    slant = surface_slant(depth, (f, f))
    assert float(slant[20, 20]) == pytest.approx(np.tan(t), rel=0.05, abs=1e-9)


def test_surface_slant_keeps_each_side_of_a_depth_edge():
    depth = torch.full((H, W), 3.0)
    depth[:, 25:] = 1.5  # two fronto-parallel planes
    depth[5, 5] = 0.0  # unknown depth
    slant = surface_slant(depth, (50.0, 50.0))
    assert float(slant[10, 24]) == 0.0 and float(slant[10, 25]) == 0.0
    assert torch.isinf(slant[5, 5])


def test_slant_limit_stops_growth_into_the_floor():
    """A walker (a fronto-parallel slab) on a floor of its own colour and depth: without the focal lengths the
    grower runs from the feet into the floor, with them it stops at the grazing floor."""
    f = 50.0
    floor = _plane_depth((0.0, -1.0, 0.0), -1.5, f).float()  # camera 1.5 m above the floor, looking level
    depth = torch.where(floor > 0, floor, torch.full_like(floor, 30.0)).clamp(max=30.0)
    walker = torch.zeros(H, W, dtype=torch.bool)
    feet = int((H - 1) / 2 + 1.5 * f / 5.0)  # the floor's row at 5 m (seen at tan θ = 5 / 1.5 there)
    walker[feet - 25:feet + 1, 20:30] = True
    depth[walker] = 5.0
    img = torch.full((H, W, 3), 0.5)
    seed = torch.zeros(H, W, dtype=torch.bool)
    seed[feet - 20:feet - 10, 22:28] = True
    params = DetectionParams(grow_steps=40)
    leaked = refine_mask(seed, img, depth, params).mask
    assert (leaked & ~walker).sum() >= 20  # the floor between 4.25 and 5.75 m joins the walker
    kept = refine_mask(seed, img, depth, params, focal=(f, f)).mask
    assert not (kept & ~walker).any()
    assert (kept & walker).sum() >= 0.95 * walker.sum()


def test_depth_step_limit_stops_growth_into_a_wall_behind():
    """A walker at 3 m before a wall of its colour at 3.3 m (within depth_rel_tol of it): the wall joins
    only when a label may cross the 10 % depth step."""
    img = torch.full((H, W, 3), 0.5)
    depth = torch.full((H, W), 3.3)
    walker = torch.zeros(H, W, dtype=torch.bool)
    walker[10:30, 20:28] = True
    depth[walker] = 3.0
    seed = torch.zeros(H, W, dtype=torch.bool)
    seed[15:25, 22:26] = True
    leaked = refine_mask(seed, img, depth, DetectionParams(grow_steps=40, depth_step_tol=0.0)).mask
    assert (leaked & ~walker).sum() > 100
    kept = refine_mask(seed, img, depth, DetectionParams(grow_steps=40)).mask
    assert torch.equal(kept, walker)
