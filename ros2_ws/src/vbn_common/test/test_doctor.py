"""vbn doctor and the dds_probe executable exchange messages over real DDS."""
from __future__ import annotations

import shutil
import uuid

import pytest

from vbn_common.dds_probe import ping

pytestmark = pytest.mark.integration


def test_vbn_doctor_reports_rmw_and_a_two_process_exchange(start_process):
    proc = start_process(['vbn', 'doctor', '--timeout', '60'])
    assert proc.wait(timeout=90) == 0, proc.output
    out = proc.output
    assert 'rmw:           rmw_fastrtps_cpp' in out
    assert 'verdict:       OK' in out
    published = out.split('published:     "')[1].split('"')[0]
    echoed = out.split('echoed back:   "')[1].split('"')[0]
    assert published == echoed and 'nonce' in published


def test_dds_probe_executable_echoes_our_ping(start_process, ros_node):
    # The installed executable, as `ros2 run visibility_builder dds_probe echo` would run it.
    exe = shutil.which('dds_probe')
    assert exe and exe.endswith('lib/vbn_common/dds_probe')
    suffix = '_' + uuid.uuid4().hex[:8]
    start_process([exe, 'echo', '--suffix', suffix])
    text = f'ping {uuid.uuid4().hex}'
    result = ping(ros_node.node, text, suffix=suffix, timeout_s=60,
                  executor=ros_node.executor)
    assert result.ok, result.detail
    assert result.message == text
