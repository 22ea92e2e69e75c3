"""The ROS 2 environment check (no rclpy) and the type hash of generated message classes."""
from __future__ import annotations

from pathlib import Path
import sys

import pytest

from vbn_common.errors import VbnCommonError
from vbn_common.ros_environment import (
    DISCOVERY_RANGES,
    DOMAIN_ID_MAX,
    check_ros_environment,
    installed_rmw_implementations,
    ros_environment_problems,
)

INSTALLED = ('rmw_fastrtps_cpp',)


@pytest.mark.parametrize('environ', [
    {},
    {'ROS_DOMAIN_ID': ''},
    {'ROS_DOMAIN_ID': '0'},
    {'ROS_DOMAIN_ID': '101'},
    {'ROS_DOMAIN_ID': str(DOMAIN_ID_MAX)},
    {'ROS_DOMAIN_ID': ' 7 '},
    {'RMW_IMPLEMENTATION': 'rmw_fastrtps_cpp'},
    {'RMW_IMPLEMENTATION': ''},
    {'ROS_LOCALHOST_ONLY': '1'},
    {'ROS_LOCALHOST_ONLY': '0'},
    *({'ROS_AUTOMATIC_DISCOVERY_RANGE': value} for value in DISCOVERY_RANGES),
])
def test_usable_environments_have_no_problems(environ: dict[str, str]) -> None:
    assert ros_environment_problems(environ, INSTALLED) == []
    check_ros_environment(environ, INSTALLED)


@pytest.mark.parametrize(('variable', 'value', 'allowed'), [
    ('ROS_DOMAIN_ID', 'abc', f'0-{DOMAIN_ID_MAX}'),
    ('ROS_DOMAIN_ID', '-1', f'0-{DOMAIN_ID_MAX}'),
    ('ROS_DOMAIN_ID', '0x10', f'0-{DOMAIN_ID_MAX}'),  # rcl would read 16
    ('ROS_DOMAIN_ID', '1e2', f'0-{DOMAIN_ID_MAX}'),  # rcl would read 1
    ('ROS_DOMAIN_ID', str(DOMAIN_ID_MAX + 1), f'0-{DOMAIN_ID_MAX}'),
    ('ROS_DOMAIN_ID', '300', f'0-{DOMAIN_ID_MAX}'),
    ('RMW_IMPLEMENTATION', 'rmw_cyclonedds_cpp', 'rmw_fastrtps_cpp'),
    ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'bogus', 'SUBNET, LOCALHOST, OFF, SYSTEM_DEFAULT'),
    ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'localhost', 'LOCALHOST'),  # rcl is case-sensitive
    ('ROS_LOCALHOST_ONLY', 'yes', '1, 0'),
])
def test_each_bad_value_names_variable_value_and_allowed(variable: str, value: str,
                                                         allowed: str) -> None:
    problems = ros_environment_problems({variable: value}, INSTALLED)
    assert len(problems) == 1
    assert problems[0].startswith(f'{variable}={value} ')
    assert '(allowed: ' in problems[0] and allowed in problems[0]
    with pytest.raises(VbnCommonError, match=f'^{variable}='):
        check_ros_environment({variable: value}, INSTALLED)


def test_domain_id_message_says_which_ids_avoid_ephemeral_ports() -> None:
    (problem,) = ros_environment_problems({'ROS_DOMAIN_ID': '300'}, INSTALLED)
    assert '0-101 and 215-232' in problem


def test_several_problems_are_all_reported_in_one_line() -> None:
    environ = {'ROS_DOMAIN_ID': 'abc', 'RMW_IMPLEMENTATION': 'rmw_zenoh_cpp'}
    assert len(ros_environment_problems(environ, INSTALLED)) == 2
    with pytest.raises(VbnCommonError) as info:
        check_ros_environment(environ, INSTALLED)
    message = str(info.value)
    assert '\n' not in message
    assert 'ROS_DOMAIN_ID=abc' in message and 'RMW_IMPLEMENTATION=rmw_zenoh_cpp' in message


def test_unknown_rmw_is_not_judged_when_no_implementation_was_found() -> None:
    assert ros_environment_problems({'RMW_IMPLEMENTATION': 'rmw_zenoh_cpp'}, ()) == []


def _fake_prefix(root: Path, registered: list[str], libraries: list[str]) -> Path:
    index = root / 'share' / 'ament_index' / 'resource_index' / 'rmw_typesupport'
    index.mkdir(parents=True)
    for name in registered:
        (index / name).write_text('')
    (root / 'lib').mkdir()
    for name in libraries:
        (root / 'lib' / f'lib{name}.so').write_text('')
    return root


def test_installed_rmw_needs_index_entry_and_library(tmp_path: Path) -> None:
    first = _fake_prefix(
        tmp_path / 'a', ['rmw_implementation', 'rmw_fastrtps_cpp', 'rmw_cyclonedds_cpp'],
        ['rmw_implementation', 'rmw_fastrtps_cpp'])  # cyclonedds registered, library gone
    second = _fake_prefix(tmp_path / 'b', ['rmw_zenoh_cpp'], ['rmw_zenoh_cpp'])
    assert installed_rmw_implementations([first, second, tmp_path / 'missing']) == (
        'rmw_fastrtps_cpp', 'rmw_zenoh_cpp')


def test_installed_rmw_here_is_fast_dds() -> None:
    # The Jazzy wheels install only Fast DDS; rcl links it directly.
    assert installed_rmw_implementations() == ('rmw_fastrtps_cpp',)


def test_environment_module_does_not_load_rclpy() -> None:
    # It must run before rclpy is imported: a bad RMW_IMPLEMENTATION ends the process on load.
    import subprocess
    code = ('import sys; import vbn_common.ros_environment as e; '
            'e.check_ros_environment(); print("rclpy" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == 'False'


def test_message_type_hash_of_pose_stamped_is_jazzy_s() -> None:
    from geometry_msgs.msg import PoseStamped
    from rosbags.typesys import Stores, get_typestore

    from vbn_common.ros_tools.msgtypes import message_type_hash

    jazzy = get_typestore(Stores.ROS2_JAZZY).hash_rihs01('geometry_msgs/msg/PoseStamped')
    assert message_type_hash(PoseStamped) == jazzy
    assert jazzy == 'RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8'


def test_message_type_hash_matches_the_installed_type_description() -> None:
    # The generator writes the same hash into share/<pkg>/msg/<Type>.json.
    import json

    from std_msgs.msg import String

    from vbn_common.ros_tools.msgtypes import message_type_hash

    json_path = Path(sys.prefix) / 'share' / 'std_msgs' / 'msg' / 'String.json'
    hashes = {h['type_name']: h['hash_string']
              for h in json.loads(json_path.read_text())['type_hashes']}
    assert message_type_hash(String) == hashes['std_msgs/msg/String']


@pytest.mark.parametrize('not_a_message', [int, str, VbnCommonError])
def test_message_type_hash_of_other_classes_is_none(not_a_message: type) -> None:
    from vbn_common.ros_tools.msgtypes import message_type_hash
    assert message_type_hash(not_a_message) is None


def test_doctor_tf2_report_without_tf2_msgs(monkeypatch: pytest.MonkeyPatch) -> None:
    from vbn_common.cli import doctor
    from vbn_common.ros_tools import msgtypes

    monkeypatch.setattr(msgtypes, 'import_message_class', lambda _msgtype: None)
    lines, problem = doctor._tf2_report()
    assert lines == ['tf2_msgs:      not importable (run make setup)']
    assert problem == ''  # not importable alone does not fail the verdict


def test_doctor_tf2_report_flags_a_hash_mismatch(monkeypatch: pytest.MonkeyPatch) -> None:
    from vbn_common.cli import doctor
    from vbn_common.ros_tools import msgtypes

    monkeypatch.setattr(msgtypes, 'message_type_hash', lambda _cls: 'RIHS01_' + '0' * 64)
    lines, problem = doctor._tf2_report()
    assert lines[-1].endswith('MISMATCH')
    assert problem.startswith('tf2_msgs/msg/TFMessage was built with type hash RIHS01_000')


def test_doctor_tf2_report_here_matches_jazzy() -> None:
    from vbn_common.cli import doctor

    lines, problem = doctor._tf2_report()
    assert problem == ''
    assert lines[0].startswith('tf2_msgs:      importable (')
    assert lines[-1].endswith(': match')


def test_rcl_error_at_init_becomes_one_line() -> None:
    # The backstop for what the environment check cannot see: rcl's own message, one line,
    # without the C source location rcl appends.
    import rclpy

    from vbn_common.ros_tools.session import rcl_errors_as_one_line

    context = rclpy.Context()
    with pytest.raises(VbnCommonError) as info:
        with rcl_errors_as_one_line('initialise ROS 2'):
            rclpy.init(args=['vbn', '--ros-args', '-r'], context=context)
    message = str(info.value)
    assert message.startswith('cannot initialise ROS 2: failed to initialize rcl: ')
    assert '-r flag' in message
    assert '\n' not in message and ', at /' not in message
    context.try_shutdown()
