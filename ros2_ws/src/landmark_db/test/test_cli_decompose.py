"""``vbn decompose`` and ``vbn validate`` through the real dispatcher, in-process."""
from __future__ import annotations

from importlib import metadata
import json

import pytest

from vbn_common.cli import main as cli_main

_OURS = {
    'decompose': 'landmark_db.cli.decompose:register',
    'validate': 'landmark_db.cli.validate:register',
}


@pytest.fixture(autouse=True)
def our_commands(monkeypatch):
    """Make sure the two commands are registered even without a colcon install."""
    real = metadata.entry_points

    def entry_points(**kwargs):
        found = list(real(**kwargs))
        if kwargs.get('group') == 'vbn.commands':
            names = {e.name for e in found}
            found += [metadata.EntryPoint(name, value, 'vbn.commands')
                      for name, value in _OURS.items() if name not in names]
        return found

    monkeypatch.setattr(cli_main.metadata, 'entry_points', entry_points)


def write(path, data):
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return str(path)


LINE = {'poses': [[0, 0], [1, 0], [2, 0], [3, 0], [4, 0]],
        'edges': [[0, 1], [1, 2], [2, 3], [3, 4]],
        'visible': [[10, 11], [10, 11], [10, 12], [11, 12], [11, 12]], 'spacing': 1.0}


def vbn(*argv):
    return cli_main.main(list(argv))


def test_decompose_then_validate(tmp_path, capsys):
    world = write(tmp_path / 'w.json', LINE)
    out = tmp_path / 'd.json'
    assert vbn('decompose', world, '--algorithm', 'B2', '--k', '1', '--out', str(out)) == 0
    assert 'B2: 2 regions' in capsys.readouterr().out
    data = json.loads(out.read_text())
    assert data['algorithm'] == 'B2' and data['k'] == 1 and data['uncovered'] == []
    # 11 is seen most (poses 0, 1, 3, 4) but in two pieces; B.2's purge keeps 2 regions.
    assert len(data['regions']) == 2
    assert sorted(p for r in data['regions'] for p in r['poses']) == [0, 1, 2, 3, 4]
    assert vbn('validate', world, str(out)) == 0
    assert capsys.readouterr().out.startswith('valid: 2 regions')


def test_decompose_prints_service_and_the_certified_bound(tmp_path, capsys):
    world = write(tmp_path / 'w.json', LINE)
    out = tmp_path / 'd.json'
    assert vbn('decompose', world, '--algorithm', 'B1', '--k', '1', '--bound',
               '--out', str(out)) == 0
    printed = capsys.readouterr().out
    assert 'served 5 of 5 k-coverable poses (100.0 %)' in printed
    # Feature 10 (poses 0-2) and 12 (poses 2-4) cover the line; no single feature does.
    assert 'fewer than 2 regions; 2 / 2 = 1.000' in printed
    assert json.loads(out.read_text())['lower_bound'] == 2
    assert vbn('validate', world, str(out)) == 0
    assert 'served 5 of 5' in capsys.readouterr().out


@pytest.mark.parametrize('algorithm', ['A1', 'A2', 'A3', 'B1', 'B2', 'C', 'exact', 'best'])
def test_every_algorithm_from_the_command_line(tmp_path, capsys, algorithm):
    world = write(tmp_path / 'w.json', LINE)
    out = str(tmp_path / 'd.json')
    assert vbn('decompose', world, '--algorithm', algorithm, '--k', '2', '--rho', '1',
               '--sigma', '0', '--seed', '3', '--out', out) == 0
    assert vbn('validate', world, out) == 0


def test_validate_exits_1_and_lists_problems(tmp_path, capsys):
    world = write(tmp_path / 'w.json', LINE)
    bad = write(tmp_path / 'd.json', {
        'algorithm': 'B1', 'k': 1, 'rho': 0, 'sigma': 0, 'seconds': 0.0,
        'regions': [{'poses': [0, 2], 'features': [10]}], 'uncovered': []})
    assert vbn('validate', world, bad) == 1
    out = capsys.readouterr().out
    assert out.startswith('INVALID')
    assert 'region 0 is not connected' in out
    assert 'lie in no region' in out


@pytest.mark.parametrize('world, extra, message', [
    ({**LINE, 'edges': [[0, 9]]}, [], 'edge 0 = [0, 9] has a pose index out of range'),
    ({**LINE, 'poses': [[0, 0], [1, 0], [2, 'nan'], [3, 0], [4, 0]]}, [], 'numbers'),
    ('{"poses": [[0, 0], [1, NaN]], "edges": [], "visible": [[], []]}', [], 'non-finite'),
    ({**LINE, 'visible': [[1], [-4], [], [], []]}, [], 'negative feature id -4'),
    ({**LINE, 'visible': [[1]]}, [], "5 poses but 'visible' has 1"),
    ({**LINE, 'poses': [[0, 0], [1, 0], [1, 0], [3, 0], [4, 0]]}, [],
     'poses 1 and 2 are both at (1, 0)'),
    ({'poses': [], 'edges': []}, [], "no 'visible'"),
    ('{"poses": [[0, 0]', [], 'not valid JSON'),
    (LINE, ['--k', '0'], '--k must be at least 1'),
    (LINE, ['--rho', '-1'], '--rho must be at least 0'),
    (LINE, ['--sigma', '-1'], '--sigma must be at least 0'),
    (LINE, ['--alpha', '0'], '--alpha must be in (0, 1]'),
])
def test_bad_input_is_one_line_and_nonzero(tmp_path, capsys, world, extra, message):
    path = write(tmp_path / 'w.json', world)
    argv = ['decompose', path, '--algorithm', 'B1', '--out', str(tmp_path / 'd.json')]
    argv += extra if '--k' in extra else ['--k', '1', *extra]
    assert vbn(*argv) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count('\n') == 1 and 'Traceback' not in err
    assert not (tmp_path / 'd.json').exists()


def test_missing_files_and_bad_decomposition(tmp_path, capsys):
    world = write(tmp_path / 'w.json', LINE)
    assert vbn('validate', world, str(tmp_path / 'none.json')) == 2
    assert 'no such file' in capsys.readouterr().err
    broken = write(tmp_path / 'd.json', {'algorithm': 'B1', 'k': 1})
    assert vbn('validate', world, broken) == 2
    assert "no 'rho'" in capsys.readouterr().err
    assert vbn('decompose', str(tmp_path / 'none.json'), '--algorithm', 'B1', '--k', '1',
               '--out', str(tmp_path / 'x.json')) == 2
    assert 'no such file' in capsys.readouterr().err


def test_unknown_algorithm_is_an_argparse_error(tmp_path, capsys):
    world = write(tmp_path / 'w.json', LINE)
    with pytest.raises(SystemExit) as exit_info:
        vbn('decompose', world, '--algorithm', 'D', '--k', '1', '--out', 'x.json')
    assert exit_info.value.code == 2
    assert 'invalid choice' in capsys.readouterr().err


def test_exact_refusal_is_a_clean_error(tmp_path, capsys):
    n = 30
    world = {'poses': [[i, 0] for i in range(n)], 'edges': [[i, i + 1] for i in range(n - 1)],
             'visible': [list(range(40)) for _ in range(n)]}
    path = write(tmp_path / 'w.json', world)
    assert vbn('decompose', path, '--algorithm', 'exact', '--k', '4', '--out',
               str(tmp_path / 'd.json')) == 2
    assert 'exact solver refused' in capsys.readouterr().err


def test_no_k_coverable_pose_is_one_line_and_nonzero(tmp_path, capsys):
    world = write(tmp_path / 'w.json', LINE)
    assert vbn('decompose', world, '--algorithm', 'best', '--k', '3',
               '--out', str(tmp_path / 'd.json')) == 2
    err = capsys.readouterr().err
    assert 'no pose of' in err and 'k = 3' in err and 'most any pose sees is 2' in err
    assert 'Traceback' not in err and not (tmp_path / 'd.json').exists()


def test_a_disconnected_pose_graph_gets_a_region_per_piece(tmp_path, capsys):
    # Two strips 8 m apart with the same features: no region may span the gap.
    world = write(tmp_path / 'w.json', {
        'poses': [[0, 0], [1, 0], [2, 0], [10, 0], [11, 0], [12, 0]],
        'edges': [[0, 1], [1, 2], [3, 4], [4, 5]], 'visible': [[1, 2, 3]] * 6})
    for algorithm in ('A1', 'B2', 'exact', 'best'):
        out = tmp_path / f'{algorithm}.json'
        assert vbn('decompose', world, '--algorithm', algorithm, '--k', '2', '--rho', '1',
                   '--out', str(out)) == 0
        regions = json.loads(out.read_text())['regions']
        assert sorted(r['poses'] for r in regions) == [[0, 1, 2], [3, 4, 5]], algorithm
        assert vbn('validate', world, str(out)) == 0
        assert 'served 6 of 6' in capsys.readouterr().out
