"""Config loading: inheritance, overrides, unknown keys, types."""

import pytest

from droidw_cli.config import load_config, parse_overrides
from droidw_cli.errors import ConfigError


def test_defaults_match_official_values():
    cfg = load_config("default")
    assert cfg.uncertainty.gamma_data == 0.1 and cfg.uncertainty.gamma_prior == 0.05
    assert cfg.uncertainty.lr == 0.01 and cfg.uncertainty.weight_decay == 0.002  # 0.1 oscillates, see default.yaml
    assert cfg.frontend.window == 25 and cfg.frontend.max_edges == 75
    assert cfg.motion_filter.thresh == 3.0
    assert cfg.ba.uncertainty == cfg.uncertainty  # the BA's copy follows the uncertainty section


def test_inheritance_chain(tmp_path):
    parent = tmp_path / "parent.yaml"
    parent.write_text("inherit_from: fast\nfrontend:\n  window: 11\n")
    child = tmp_path / "child.yaml"
    child.write_text("inherit_from: parent.yaml\nfrontend:\n  radius: 3\n")
    cfg = load_config(child)
    assert cfg.frontend.window == 11  # from parent
    assert cfg.frontend.radius == 3  # from child
    assert cfg.io.target_area == 98304  # from fast.yaml
    assert cfg.frontend.max_edges == 40  # fast.yaml, untouched by the children


def test_overrides_and_types():
    cfg = load_config("default", ["frontend.window=30", "uncertainty.enable=false", "ba.gamma_depth=1"])
    assert cfg.frontend.window == 30
    assert cfg.uncertainty.enable is False and cfg.ba.uncertainty.enable is False
    assert isinstance(cfg.ba.gamma_depth, float) and cfg.ba.gamma_depth == 1.0
    assert load_config("default", ["ba.gamma_depth=1e-3"]).ba.gamma_depth == 0.001  # YAML 1.1 reads it as text
    assert parse_overrides(["a.b.c=1.5", "a.d=x"]) == {"a": {"b": {"c": 1.5}, "d": "x"}}


def test_unknown_key_names_key_and_file(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("inherit_from: default\nfrontend:\n  windw: 3\n")
    with pytest.raises(ConfigError) as exc:
        load_config(bad)
    assert "frontend.windw" in str(exc.value) and str(bad) in str(exc.value)
    with pytest.raises(ConfigError, match="--set: unknown config key 'nope'"):
        load_config("default", ["nope.x=1"])


@pytest.mark.parametrize("override, message", [
    ("frontend.window=abc", "must be an integer"),
    ("ba.gamma_depth=abc", "must be a number"),
    ("ba.gamma_depth=nan", "must be a number"),
    ("uncertainty.enable=3", "true or false"),
    ("uncertainty.mode=bogus", "uncertainty.mode"),
    ("frontend", "expected key.sub=value"),
    ("dynamics.track_min_new=1.5", "track_min_new"),
    ("frontend.window=2", "window > radius"),  # crashed in initialisation (its 2nd predecessor's image was gone)
    ("frontend.window=-5", "window > radius"),
    ("frontend.warmup_min=1", "warmup_min"),
    ("frontend.iters1=0", "iters1"),
    ("frontend.beta=1.5", "beta"),
    ("frontend.flow_thresh=0", "flow_thresh"),
    ("threads=-1", "threads"),
])
def test_bad_values(override, message):
    with pytest.raises(ConfigError, match=message):
        load_config("default", [override])


def test_missing_config_and_cycle(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.yaml")
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text("inherit_from: b.yaml\n")
    b.write_text("inherit_from: a.yaml\n")
    with pytest.raises(ConfigError, match="cycle"):
        load_config(a)


def test_builtin_configs_all_load():
    for name in ("default", "tum", "rgbd", "video", "fast"):
        load_config(name)
    assert load_config("rgbd").io.use_depth is True


def test_invalid_yaml_is_one_line_with_its_place(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("frontend:\n  window: [3\n")
    with pytest.raises(ConfigError) as exc:
        load_config(bad)
    message = str(exc.value)
    assert "\n" not in message and "invalid YAML" in message and "line 3" in message, message
