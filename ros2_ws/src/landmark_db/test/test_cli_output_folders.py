"""Every ``--out`` of the landmark_db commands names a missing output folder in one line.

Regression test: writing into a missing folder used to report the internal temporary
file name (``.w.json.k2j3h4.tmp``) instead of the folder the user mistyped.
"""
from __future__ import annotations

from importlib import metadata
import json
from pathlib import Path

import pytest

from vbn_common.cli import main as cli_main

_OURS = {
    'simulate': 'vbn_worlds.cli.simulate:register',
    'decompose': 'landmark_db.cli.decompose:register',
    'bench-decomposition': 'vbn_bench.cli.bench_decomposition:register',
}

LINE = {'poses': [[0, 0], [1, 0], [2, 0]], 'edges': [[0, 1], [1, 2]],
        'visible': [[10, 11], [10, 11], [10, 12]], 'spacing': 1.0}


@pytest.fixture(autouse=True)
def our_commands(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make sure the commands are registered even without a colcon install."""
    real = metadata.entry_points

    def entry_points(**kwargs: object) -> list[metadata.EntryPoint]:
        found = list(real(**kwargs))
        if kwargs.get('group') == 'vbn.commands':
            names = {e.name for e in found}
            found += [metadata.EntryPoint(name, value, 'vbn.commands')
                      for name, value in _OURS.items() if name not in names]
        return found

    monkeypatch.setattr(cli_main.metadata, 'entry_points', entry_points)


def _one_line_error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    captured = capsys.readouterr()
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1, captured.err
    assert 'Traceback' not in captured.err and '.tmp' not in captured.err
    assert lines[0].startswith(f'vbn {command}: error: ')
    return lines[0]


@pytest.mark.parametrize('option', ['--out', '--scene-out'])
def test_simulate_into_missing_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                      option: str) -> None:
    missing = tmp_path / 'no_such_folder'
    paths = {'--out': str(tmp_path / 'w.json'), '--scene-out': str(tmp_path / 's.json')}
    paths[option] = str(missing / 'x.json')
    code = cli_main.main(['simulate', '--setting', '2', '--seed', '7', '--small',
                          '--out', paths['--out'], '--scene-out', paths['--scene-out']])
    assert code == 2
    assert _one_line_error(capsys, 'simulate').endswith(
        f'output folder {missing} does not exist')
    # Checked before simulating: nothing else was written either.
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_decompose_into_missing_folder(tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    world = tmp_path / 'w.json'
    world.write_text(json.dumps(LINE))
    missing = tmp_path / 'results' / 'run1'
    code = cli_main.main(['decompose', str(world), '--algorithm', 'B2', '--k', '1',
                          '--out', str(missing / 'd.json')])
    assert code == 2
    assert _one_line_error(capsys, 'decompose').endswith(
        f'output folder {missing} does not exist')


def test_decompose_relative_out_names_the_folder_as_typed(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    Path('w.json').write_text(json.dumps(LINE))
    code = cli_main.main(['decompose', 'w.json', '--algorithm', 'A1', '--k', '1',
                          '--out', 'missing/d.json'])
    assert code == 2
    assert _one_line_error(capsys, 'decompose') == (
        'vbn decompose: error: output folder missing does not exist')


def test_bench_decomposition_into_missing_parent(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    missing = tmp_path / 'no_such_folder'
    code = cli_main.main(['bench-decomposition', '--worlds', '1', '--settings', '2',
                          '--out', str(missing / 'bench')])
    assert code == 2
    assert _one_line_error(capsys, 'bench-decomposition').endswith(
        f'output folder {missing} does not exist')
    assert not missing.exists()


def test_bench_decomposition_out_that_is_a_file(tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / 'bench').write_text('x')
    code = cli_main.main(['bench-decomposition', '--worlds', '1', '--settings', '2',
                          '--out', str(tmp_path / 'bench')])
    assert code == 2
    assert _one_line_error(capsys, 'bench-decomposition').endswith(
        f'output folder {tmp_path / "bench"} is a file')
