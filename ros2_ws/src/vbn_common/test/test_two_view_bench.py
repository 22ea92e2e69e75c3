"""Benchmark: median pose error of each two-view method against pixel noise.

Runs ``ros2_ws/test_support/two_view_bench.py`` in a fresh interpreter (single-threaded OpenBLAS,
as the localizer should run) and prints its Markdown table (docs/localization.md).
"""
from __future__ import annotations

import os
import subprocess
import sys

from paths import SUPPORT
import pytest

SCRIPT = SUPPORT / 'two_view_bench.py'


@pytest.mark.bench
def test_two_view_error_against_pixel_noise():
    trials = os.environ.get('TWO_VIEW_TRIALS', '200')
    out = subprocess.run([sys.executable, str(SCRIPT), trials], capture_output=True,
                         text=True, check=True, timeout=3000, cwd=SCRIPT.parent)
    print(out.stdout)
    noise_table = out.stdout.split('\n\n')[0]
    rows = [line for line in noise_table.splitlines() if line.startswith('| pan')
            or line.startswith('| pin')]
    assert len(rows) == 9
    for row in rows:
        if 'linear_combination' in row:
            continue
        # exact without noise: the 0 px cell reads "0.0 mm / 0.000 deg"
        assert row.split('|')[3].strip() == '0.0 mm / 0.000 deg', row
