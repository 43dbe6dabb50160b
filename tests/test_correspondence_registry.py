"""The correspondence-source registry: built-in dis, entry-point plugins, unknown names."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from droidw_cli.config import CorrespondenceConfig
from droidw_cli.correspondence import (
    Correspondence,
    CorrespondenceSource,
    DISCorrespondence,
    available_correspondence_sources,
    get_correspondence_source,
)
from droidw_cli.correspondence import registry
from droidw_cli.correspondence.grid import grid_coordinates
from droidw_cli.errors import UserError

from fake_plugins import FakeEntryPoint, plug_entry_points


class IdentitySource(CorrespondenceSource):
    name = "identity"

    def __init__(self, cfg):
        self.cfg = cfg

    def match(self, image_i, image_j, init_flow=None):
        h, w = image_i.shape[:2]
        g = torch.from_numpy(grid_coordinates(h // 8, w // 8).copy())
        return Correspondence(np.zeros((h, w, 2), np.float32), g, torch.ones_like(g))


def plug(monkeypatch, *eps):
    plug_entry_points(monkeypatch, registry, *eps)


def test_builtin_dis_uses_the_config():
    src = get_correspondence_source(CorrespondenceConfig(name="dis", preset="fast", fb_thresh=2.0))
    assert isinstance(src, DISCorrespondence) and src.cfg.preset == "fast" and src.cfg.fb_thresh == 2.0
    assert "dis" in available_correspondence_sources()


def test_unknown_name_lists_known(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("identity", IdentitySource))
    with pytest.raises(UserError, match=r"unknown correspondence source 'raft' \(known: dis, identity\)"):
        get_correspondence_source(CorrespondenceConfig(name="raft"))


def test_plugin_found_and_default_helpers_work(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("identity", IdentitySource))
    src = get_correspondence_source(CorrespondenceConfig(name="identity"))
    assert isinstance(src, IdentitySource)
    img = np.zeros((16, 24, 3), np.uint8)
    assert src.mean_flow(img, img) == 0.0  # the base-class default runs match()
    targets, weights = src.match_many([(img, img)] * 3)
    assert targets.shape == (3, 2, 3, 2) and torch.all(weights == 1)


def test_broken_plugins_are_user_errors(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("broken", ImportError("no module")), FakeEntryPoint("wrong", lambda cfg: 42))
    with pytest.raises(UserError, match="failed to load: no module"):
        get_correspondence_source(CorrespondenceConfig(name="broken"))
    with pytest.raises(UserError, match="not a CorrespondenceSource"):
        get_correspondence_source(CorrespondenceConfig(name="wrong"))
