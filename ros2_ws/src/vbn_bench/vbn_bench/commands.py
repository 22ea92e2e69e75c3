"""The project's commands as the benchmarks and the demo run them: imported, not spawned.

A benchmark renders worlds, builds databases and localizes runs. It calls each command
through its imported ``register`` function (:func:`vbn_common.cli.main.run_registered`),
so that the package rules see what it stands on and the command parses, reports and fails
exactly as on the command line, with its output in the benchmark's log.

``isolated=True`` runs the command in a fresh interpreter (``multiprocessing``'s spawn
start method) with the given environment: a localization timed on one core needs its
BLAS thread count set before numpy loads, and a build measured for memory needs a
process of its own.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
import multiprocessing
import os
from pathlib import Path
from typing import Any

from landmark_db.cli import db_export, db_info, decompose
from vbn_bench.cli import localize
from vbn_bench.errors import BenchError
from vbn_common.cli.main import run_registered
from vbn_worlds.cli import render, simulate
from visibility_builder.cli import build, db_update, estimate_poses

__all__ = ['COMMANDS', 'run_command', 'start_isolated']

#: The commands a benchmark may run, by their ``vbn`` name.
COMMANDS: dict[str, Callable[[Any], None]] = {
    'build': build.register, 'db-update': db_update.register,
    'estimate-poses': estimate_poses.register, 'render': render.register,
    'simulate': simulate.register, 'localize': localize.register,
    'decompose': decompose.register, 'db-info': db_info.register,
    'db-export': db_export.register,
}


def _register(name: str) -> Callable[[Any], None]:
    if name not in COMMANDS:
        raise BenchError(f'no command {name!r} for a benchmark ({", ".join(COMMANDS)})')
    return COMMANDS[name]


def _child(argv: list[str], log: str, append: bool, env: dict[str, str]) -> None:
    os.environ.update(env)
    raise SystemExit(run_registered(COMMANDS[argv[0]], argv, log, append))


def start_isolated(argv: Sequence[str], log: str | Path, *, append: bool = False,
                   env: Mapping[str, str] | None = None) -> multiprocessing.process.BaseProcess:
    """Start ``vbn ARGV`` in a fresh interpreter; the caller joins it.

    Returns:
        The started process (its ``pid`` for a memory sampler, ``exitcode`` once joined).
    """
    argv = list(argv)
    _register(argv[0])
    process = multiprocessing.get_context('spawn').Process(
        target=_child, args=(argv, str(log), append, dict(env or {})),
        name=f'vbn {argv[0]}')
    process.start()
    return process


def run_command(argv: Sequence[str], log: str | Path, *, append: bool = True,
                env: Mapping[str, str] | None = None, isolated: bool = False) -> None:
    """Run ``vbn ARGV`` with its output in ``log``.

    Args:
        argv: The command's name and arguments, e.g. ``['build', BAG, '--db', DB]``.
        log: The file that takes everything the command prints.
        append: Add to ``log`` rather than replace it.
        env: Environment variables for the command (only with ``isolated``).
        isolated: In a fresh interpreter (see the module docstring).

    Raises:
        BenchError: ``vbn NAME failed (exit N); see LOG`` when it did not exit with 0.
    """
    argv = list(argv)
    register = _register(argv[0])
    if isolated:
        process = start_isolated(argv, log, append=append, env=env)
        try:
            process.join()
        except BaseException:
            process.terminate()
            process.join()
            raise
        code = process.exitcode
    else:
        if env:
            raise BenchError('an environment needs an isolated command')
        code = run_registered(register, argv, log, append)
    if code != 0:
        raise BenchError(f'vbn {argv[0]} failed (exit {code}); see {log}')
