"""``vbn demo`` (what ``make demo`` runs): build, node, record, play over DDS, evaluate.

About 90 s on the 2-core machine, so it is a benchmark (``pytest -m bench``).
"""
from __future__ import annotations

import json
from pathlib import Path
import subprocess

from paths import REPO
import pytest

pytestmark = [pytest.mark.integration, pytest.mark.bench]

ROOT = REPO


def test_demo_passes_and_writes_its_figure(tmp_path: Path, ros_env) -> None:
    out = tmp_path / 'demo'
    proc = subprocess.run(['vbn', 'demo', '--out', str(out)], capture_output=True, text=True,
                          timeout=600, env=ros_env, cwd=ROOT)
    lines = proc.stdout.strip().splitlines()
    assert lines[-1] == 'PASS', proc.stdout + proc.stderr
    assert proc.returncode == 0
    results = json.loads((out / 'results.json').read_text())
    assert results['frames'] == 439
    assert results['evo']['matched'] == results['poses'] > 0
    assert results['evo']['translation_median_m'] == pytest.approx(
        results['accuracy']['translation_median_m'], abs=1e-6)
    assert all(c['passed'] for c in results['checks'])
    assert (out / 'trajectory.png').stat().st_size > 10_000
    # The node published a pose for at most the frames it processed.
    assert results['poses'] <= int(results['diagnostics']['frames_processed']) <= 439
