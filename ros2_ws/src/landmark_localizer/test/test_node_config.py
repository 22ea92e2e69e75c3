"""The localizer node's defaults file equals the code's defaults; every parameter is described."""
from __future__ import annotations

from dataclasses import asdict

from paths import REPO
import pytest
import yaml

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from landmark_localizer.parameters import NodeSettings, config_descriptions

YAML = REPO / 'ros2_ws' / 'src' / 'landmark_localizer' / \
    'config' / 'localizer.yaml'


def test_yaml_defaults_equal_the_code_defaults() -> None:
    params = yaml.safe_load(YAML.read_text())['localizer']['ros__parameters']
    assert params == {**asdict(NodeSettings()), **LocalizerConfig().as_dict()}


def test_node_and_core_names_do_not_collide() -> None:
    assert not set(asdict(NodeSettings())) & set(LocalizerConfig().as_dict())


@pytest.mark.parametrize('cls', [NodeSettings, LocalizerConfig])
def test_every_parameter_has_a_description(cls) -> None:
    descriptions = config_descriptions(cls)
    assert [name for name, text in descriptions.items() if len(text) < 8] == []


def test_descriptions_join_continuation_lines() -> None:
    text = config_descriptions(NodeSettings)['transform_tolerance']
    assert text.startswith('How far ahead') and text.endswith("(AMCL's parameter).")


def test_bad_node_settings_are_one_line_errors() -> None:
    with pytest.raises(LocalizerError, match='transform_tolerance must be a finite number'):
        NodeSettings(transform_tolerance=float('nan'))
    with pytest.raises(LocalizerError, match='three different names'):
        NodeSettings(odom_frame_id='map')


@pytest.mark.parametrize(('name', 'value', 'message'), [
    ('vote_scale', 0.0, 'vote_scale must be in'), ('vote_scale', 1.5, 'vote_scale must be in'),
    ('vote_checks', -1, 'vote_checks must be >= 0'), ('lk_window', 20, 'must be odd')])
def test_bad_core_settings_are_one_line_errors(name: str, value: object, message: str) -> None:
    with pytest.raises(LocalizerError, match=message):
        LocalizerConfig().with_values({name: value})
