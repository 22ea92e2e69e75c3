"""The vbn dispatcher: version, help, and one-line errors."""
from __future__ import annotations

from importlib import metadata

import pytest

from landmark_db import __version__
from vbn_common.cli import main as cli_main
from vbn_common.errors import VbnError


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_info:
        cli_main.main(['--version'])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f'vbn {__version__}'


def test_help_lists_installed_commands(capsys):
    with pytest.raises(SystemExit):
        cli_main.main(['--help'])
    out = capsys.readouterr().out
    assert 'doctor' in out


def test_no_command_prints_help_and_exits_0(capsys):
    assert cli_main.main([]) == 0
    assert 'usage: vbn' in capsys.readouterr().out


class _FakeEntryPoint:
    name = 'explode'

    @staticmethod
    def load():
        def register(subparsers):
            parser = subparsers.add_parser('explode')
            parser.add_argument('--kind', default='vbn')
            parser.set_defaults(func=_run)
        return register


def _run(args):
    if args.kind == 'vbn':
        raise VbnError('the world file has 3 poses but 2 visibility lists')
    raise FileNotFoundError(2, 'No such file or directory', 'missing.json')


@pytest.fixture
def fake_command(monkeypatch):
    monkeypatch.setattr(metadata, 'entry_points', lambda group: [_FakeEntryPoint()])


def test_user_error_is_one_line_and_exit_2(fake_command, capsys):
    assert cli_main.main(['explode']) == 2
    err = capsys.readouterr().err
    assert err == 'vbn explode: error: the world file has 3 poses but 2 visibility lists\n'


def test_missing_file_is_one_line_and_exit_2(fake_command, capsys):
    assert cli_main.main(['explode', '--kind', 'os']) == 2
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and 'missing.json' in err and 'Traceback' not in err

