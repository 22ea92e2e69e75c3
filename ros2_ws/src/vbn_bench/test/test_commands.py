"""The benchmarks run our commands by importing them: output in the log, failures named."""
from __future__ import annotations

from pathlib import Path

from database_samples import sample_database
import numpy as np
import pytest

from landmark_db.database import write_database
from vbn_bench.commands import COMMANDS, run_command
from vbn_bench.errors import BenchError


@pytest.fixture
def db_file(tmp_path: Path) -> Path:
    path = tmp_path / 'room.db'
    write_database(path, sample_database(np.random.default_rng(1), nx=4, ny=3, rho=1))
    return path


def test_a_command_prints_into_its_log(db_file: Path, tmp_path: Path) -> None:
    log = tmp_path / 'bench.log'
    log.write_text('$ vbn db-info\n')
    run_command(['db-info', str(db_file)], log)
    text = log.read_text()
    assert text.startswith('$ vbn db-info\n')            # appended to what was there
    assert f'{db_file}: landmark database, schema version 5, ' in text


def test_a_failed_command_names_itself_and_its_log(tmp_path: Path) -> None:
    log = tmp_path / 'bench.log'
    with pytest.raises(BenchError, match=rf'^vbn db-info failed \(exit 2\); see {log}$'):
        run_command(['db-info', str(tmp_path / 'missing.db')], log)
    assert log.read_text().strip().splitlines() == [
        f'vbn db-info: error: {tmp_path / "missing.db"}: no such file']


def test_a_usage_error_is_a_failed_command(tmp_path: Path) -> None:
    with pytest.raises(BenchError, match='vbn db-info failed .exit 2.'):
        run_command(['db-info', '--no-such-option'], tmp_path / 'bench.log')


def test_an_isolated_command_runs_in_a_fresh_interpreter(db_file: Path, tmp_path: Path
                                                         ) -> None:
    log = tmp_path / 'bench.log'
    run_command(['db-info', str(db_file)], log, isolated=True,
                env={'OPENBLAS_NUM_THREADS': '1'}, append=False)
    assert f'{db_file}: landmark database' in log.read_text()


def test_only_the_known_commands_run_and_an_environment_needs_isolation(tmp_path: Path
                                                                        ) -> None:
    assert {'build', 'render', 'localize', 'db-update', 'estimate-poses'} <= set(COMMANDS)
    with pytest.raises(BenchError, match="no command 'rm'"):
        run_command(['rm', '-rf', '/'], tmp_path / 'log')
    with pytest.raises(BenchError, match='isolated'):
        run_command(['db-info', 'x'], tmp_path / 'log', env={'A': '1'})
