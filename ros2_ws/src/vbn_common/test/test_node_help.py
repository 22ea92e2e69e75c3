"""A node's --help: usage and every parameter, printed without starting ROS."""
from __future__ import annotations

import pytest

from vbn_common.node_main import NodeParameter, format_node_help, run_node


def test_help_lists_each_parameter_with_type_default_and_when_it_applies() -> None:
    text = format_node_help('node [-h] --ros-args -p db:=FILE', 'Does one thing.', [
        NodeParameter('db', '', 'the database file', False),
        NodeParameter('autostart', True, 'configure at start-up', True),
        NodeParameter('read.image_topic', None, 'automatic', False)])
    lines = text.splitlines()
    assert lines[0] == 'usage: node [-h] --ros-args -p db:=FILE'
    assert "  db (str, default '', live)" in lines
    assert '  autostart (bool, default True, read-only)' in lines
    assert '  read.image_topic (any, default None, live)' in lines
    assert '      configure at start-up' in lines


@pytest.mark.parametrize('flag', ['-h', '--help'])
def test_run_node_prints_the_help_and_starts_nothing(flag: str, capsys) -> None:
    def make_node() -> object:
        raise AssertionError('no node may be made for --help')

    assert run_node('node', make_node, ['node', flag], help_text=lambda: 'usage: node\n') == 0
    assert capsys.readouterr().out == 'usage: node\n'


def test_a_help_flag_after_ros_args_is_not_ours(capsys, monkeypatch) -> None:
    # After --ros-args the arguments are rcl's; there -h is not the node's help. A bad
    # environment stops before ROS starts, so the test needs none.
    monkeypatch.setenv('ROS_DOMAIN_ID', 'abc')
    assert run_node('node', lambda: None, ['node', '--ros-args', '-h'],
                    help_text=lambda: 'usage\n') == 2
    assert 'ROS_DOMAIN_ID=abc' in capsys.readouterr().err
