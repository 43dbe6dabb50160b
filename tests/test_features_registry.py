"""The feature-extractor registry: built-in xfeat, entry-point plugins, unknown names."""

from __future__ import annotations

import pytest
import torch

from droidw_cli.errors import UserError
from droidw_cli.features import FeatureExtractor, available_feature_extractors, get_feature_extractor
from droidw_cli.features import registry

from fake_plugins import FakeEntryPoint, plug_entry_points


class ConstantExtractor(FeatureExtractor):
    name = "constant"
    channels = 4

    def __init__(self, device="cpu"):
        self.device = torch.device(device)

    def extract(self, images):
        b, _, h, w = images.shape
        out = torch.zeros(b, self.channels, h // 8, w // 8, device=self.device)
        out[:, 0] = 1.0
        return out


def plug(monkeypatch, *eps):
    plug_entry_points(monkeypatch, registry, *eps)


def test_builtin_xfeat():
    ext = get_feature_extractor("xfeat")
    assert ext.name == "xfeat" and ext.channels == 64 and ext.stride == 8
    assert "xfeat" in available_feature_extractors()


def test_unknown_name_lists_known(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("constant", ConstantExtractor))
    with pytest.raises(UserError, match=r"unknown feature extractor 'nope' \(known: constant, xfeat\)"):
        get_feature_extractor("nope")


def test_plugin_is_found_through_entry_points(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("constant", ConstantExtractor))
    ext = get_feature_extractor("constant")
    assert isinstance(ext, ConstantExtractor)
    assert ext.extract(torch.zeros(1, 3, 16, 24)).shape == (1, 4, 2, 3)
    assert available_feature_extractors() == ["constant", "xfeat"]


def test_broken_plugins_are_user_errors(monkeypatch):
    plug(monkeypatch, FakeEntryPoint("broken", ImportError("no module")), FakeEntryPoint("wrong", lambda device: object()))
    with pytest.raises(UserError, match="failed to load: no module"):
        get_feature_extractor("broken")
    with pytest.raises(UserError, match="not a FeatureExtractor"):
        get_feature_extractor("wrong")
