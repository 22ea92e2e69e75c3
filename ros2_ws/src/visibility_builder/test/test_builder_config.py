from __future__ import annotations

from paths import REPO
import pytest
import yaml

from visibility_builder.build import (
    BuildConfig,
    config_from_flat,
    flat_config,
    setting_descriptions,
)
from visibility_builder.errors import VisibilityBuilderError

YAML = REPO / 'ros2_ws' / 'src' / 'visibility_builder' / \
    'config' / 'builder.yaml'
NODE_ONLY = {'db', 'bag', 'idle_timeout', 'report', 'shutdown_after_build'}


def test_yaml_defaults_equal_the_code_defaults() -> None:
    params = yaml.safe_load(YAML.read_text())['builder']['ros__parameters']
    assert set(params) - NODE_ONLY == set(flat_config(BuildConfig()))
    assert {k: v for k, v in params.items() if k not in NODE_ONLY} == \
        flat_config(BuildConfig())


def test_every_setting_has_a_description() -> None:
    descriptions = setting_descriptions()
    missing = [name for name in flat_config(BuildConfig()) if not descriptions.get(name)]
    assert missing == []


def test_flat_round_trip_and_overrides() -> None:
    config = config_from_flat({'decomposition.k': 5, 'classes.gamma': 1, 'workers': 2})
    assert (config.decomposition.k, config.classes.gamma, config.workers) == (5, 1, 2)
    assert config_from_flat(flat_config(config)) == config
    with pytest.raises(VisibilityBuilderError, match="unknown build setting 'nope.k'"):
        config_from_flat({'nope.k': 1})
    with pytest.raises(VisibilityBuilderError, match='k must be an integer >= 1'):
        config_from_flat({'decomposition.k': 0})
