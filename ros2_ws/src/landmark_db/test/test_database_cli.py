"""``vbn db-info`` and ``vbn db-export`` through the real dispatcher."""
from __future__ import annotations

from importlib import metadata
import json
import os
import shutil
import subprocess
import sys

from database_samples import sample_database
import numpy as np
import pytest

from landmark_db.database import write_database
from vbn_common.cli import main as cli_main

_OURS = {
    'db-info': 'landmark_db.cli.db_info:register',
    'db-export': 'landmark_db.cli.db_export:register',
    'validate': 'landmark_db.cli.validate:register',
}


@pytest.fixture(autouse=True)
def our_commands(monkeypatch):
    """Make sure the commands are registered even without a colcon install."""
    real = metadata.entry_points

    def entry_points(**kwargs):
        found = list(real(**kwargs))
        if kwargs.get('group') == 'vbn.commands':
            names = {e.name for e in found}
            found += [metadata.EntryPoint(name, value, 'vbn.commands')
                      for name, value in _OURS.items() if name not in names]
        return found

    monkeypatch.setattr(cli_main.metadata, 'entry_points', entry_points)


def vbn(*argv):
    return cli_main.main([str(a) for a in argv])


@pytest.fixture
def db_file(tmp_path):
    path = tmp_path / 'room.db'
    db = sample_database(np.random.default_rng(1), nx=4, ny=3, rho=1)
    write_database(path, db)
    return path, db


def test_db_info_text(db_file, capsys):
    path, db = db_file
    assert vbn('db-info', path) == 0
    out = capsys.readouterr().out
    assert out.startswith(f'{path}: landmark database, schema version 5, ')
    assert f'scene points: {db.points.n_points} (3-D points' in out
    assert f'regions:     {db.n_regions} (mean' in out
    assert f'features:    {db.n_classes} classes' in out
    assert 'poses:       12, 17 edges, spacing 0.5 m' in out
    assert 'k = 2, rho = 1, sigma = 0, algorithm B2' in out
    assert 'camera:      pinhole 640 x 480, plumb_bob distortion, frame camera' in out
    assert 'gamma = 5' in out


def test_db_info_json(db_file, capsys):
    path, db = db_file
    assert vbn('db-info', path, '--json') == 0
    data = json.loads(capsys.readouterr().out)
    assert data['counts']['regions'] == db.n_regions
    assert data['counts']['poses'] == 12
    assert data['build']['rho'] == 1 and data['build']['pose_source'] == 'ground_truth'
    assert data['file_bytes'] == path.stat().st_size


def test_db_export_then_validate(db_file, tmp_path, capsys):
    path, db = db_file
    world, decomposition = tmp_path / 'w.json', tmp_path / 'd.json'
    assert vbn('db-export', path, '--world', world, '--decomposition', decomposition) == 0
    assert f'({db.n_regions} regions, k = 2)' in capsys.readouterr().out
    data = json.loads(decomposition.read_text())
    assert data['algorithm'] == 'B2' and data['rho'] == 1
    assert [r['poses'] for r in data['regions']] == [r.poses.tolist() for r in db.regions]
    assert len(json.loads(world.read_text())['poses']) == 12
    assert vbn('validate', world, decomposition) == 0
    assert capsys.readouterr().out.startswith(f'valid: {db.n_regions} regions')


@pytest.mark.parametrize('argv, message', [
    (['db-info', '{missing}'], 'none.db: no such file'),
    (['db-info', '{noise}'], 'noise.db: not a SQLite database'),
    (['db-export', '{db}'], 'nothing to export'),
    (['db-export', '{db}', '--world', '{tmp}/no/w.json'], 'output folder'),
    (['db-export', '{noise}', '--decomposition', '{tmp}/d.json'], 'not a SQLite database'),
])
def test_errors_are_one_line_exit_2(db_file, tmp_path, capsys, argv, message):
    path, _ = db_file
    noise = tmp_path / 'noise.db'
    noise.write_bytes(b'x' * 5000)
    names = {'missing': tmp_path / 'none.db', 'noise': noise, 'db': path, 'tmp': tmp_path}
    assert vbn(*[a.format(**names) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and message in err and err.startswith(f'vbn {argv[0]}: error')
    assert not (tmp_path / 'd.json').exists()


def test_installed_vbn_runs_db_info(db_file):
    """The installed ``vbn`` (colcon entry points) knows the commands."""
    path, _ = db_file
    vbn_exe = shutil.which('vbn')
    command = [vbn_exe] if vbn_exe else [sys.executable, '-m', 'vbn_common.cli.main']
    done = subprocess.run([*command, 'db-info', str(path)], capture_output=True, text=True,
                          env=dict(os.environ), timeout=120)
    if 'invalid choice' in done.stderr:
        pytest.skip('the workspace install predates db-info (run make setup)')
    assert done.returncode == 0, done.stderr
    assert 'landmark database, schema version 5' in done.stdout
