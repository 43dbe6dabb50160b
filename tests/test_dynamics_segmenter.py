"""The segmenter registry: the built-in grower, entry-point plugins (the MobileSAM slot), broken plugins."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.config import DynamicsConfig
from droidw_cli.dynamics import segmenter as registry
from droidw_cli.dynamics.inloop import KeyframeMasks
from droidw_cli.dynamics.params import DetectionParams
from droidw_cli.dynamics.refine import label_components, make_objects
from droidw_cli.errors import UserError

from fake_plugins import FakeEntryPoint, plug_entry_points


class SeedsOnly:
    """A segmenter that keeps the seed components as they are (the docs' example, docs/plugins.md)."""

    name = "seeds"

    def __init__(self, params: DetectionParams) -> None:
        self.params = params

    def segment(self, seeds, image, depth, focal=None):
        return make_objects(label_components(seeds, self.params.min_seed_area), self.params.min_object_area)


def plug(monkeypatch, *eps):
    plug_entry_points(monkeypatch, registry, *eps)


def test_plugin_is_found_and_used_by_the_keyframe_masks(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("seeds", SeedsOnly))
    assert registry.available_segmenters() == ["grow", "seeds"]
    masks = KeyframeMasks(DynamicsConfig(mode="both", segmenter="seeds"), (6, 8), consistency=True)
    assert isinstance(masks.segmenter, SeedsOnly)
    seeds = torch.zeros(6, 8, dtype=torch.bool)
    seeds[1:3, 2:5] = True
    seeds[5, 7] = True  # one pixel: under min_seed_area
    objects = masks.segmenter.segment(seeds, torch.zeros(6, 8, 3), torch.ones(6, 8), focal=(5.0, 5.0))
    assert objects.count == 1 and torch.equal(objects.mask, seeds & ~(torch.arange(8) == 7)[None, :])


def test_broken_plugins_are_user_errors(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("broken", ImportError("no module")),
         FakeEntryPoint("wrong", lambda params: object()))
    with pytest.raises(UserError, match="failed to load: no module"):
        registry.get_segmenter("broken")
    with pytest.raises(UserError, match="has no segment"):
        registry.get_segmenter("wrong")
    with pytest.raises(UserError, match=r"unknown segmenter 'mobilesam' \(known: broken, grow, wrong\)"):
        registry.get_segmenter("mobilesam")
