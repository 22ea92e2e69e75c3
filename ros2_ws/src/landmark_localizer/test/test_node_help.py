"""``localizer --help``: the usage and every parameter, exit 0, no ROS started."""
from __future__ import annotations

import subprocess

import pytest


@pytest.mark.parametrize(('executable', 'expected'), [
    ('localizer', ['usage: localizer', "  db (str, default '', live)",
                   '  autostart (bool, default True, read-only)', '  min_tracked (int']),
])
def test_the_node_prints_its_usage_and_parameters(executable: str, expected: list[str]
                                                  ) -> None:
    done = subprocess.run([executable, '--help'], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stderr == ''
    for text in expected:
        assert text in done.stdout, text
