"""vbn output piped into a reader that stops early (``vbn bag-info BAG | head -1``)."""
from __future__ import annotations

import subprocess

from paths import REPO
import pytest

BAG = REPO / 'bags' / 'room_run'


@pytest.mark.skipif(not BAG.is_dir(), reason='sample bag bags/room_run missing')
def test_closed_output_pipe_ends_quietly():
    proc = subprocess.Popen(['vbn', 'bag-info', str(BAG)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE)
    proc.stdout.close()  # the reader is gone before vbn prints anything
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 0, err
    assert b'error' not in err and b'Traceback' not in err
