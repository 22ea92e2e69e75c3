"""``vbn``: the view-based navigation command line.

Subcommands are contributed by the project's packages through the ``vbn.commands``
entry-point group. Each entry point names a ``register(subparsers)`` function that
adds one subparser and sets its ``func`` default to a ``run(args) -> int``
callable. Command modules keep heavy imports inside ``run`` so that ``vbn --help``
stays fast.
"""
from __future__ import annotations

import argparse
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from importlib import metadata
import logging
import os
from pathlib import Path
import signal
import sys
from typing import Any

from vbn_common import __version__
from vbn_common.errors import VbnError

__all__ = ['build_parser', 'main', 'run_registered']

_LOG = logging.getLogger(__name__)


def build_parser() -> argparse.ArgumentParser:
    """Build the ``vbn`` parser with every installed subcommand.

    Returns:
        The top-level parser; subcommands are sorted by name.
    """
    parser = argparse.ArgumentParser(
        prog='vbn',
        description='View-based robot navigation: build a landmark database from an '
                    'exploration bag and localize against it (ROS 2 Jazzy).',
    )
    parser.add_argument('--version', action='version', version=f'vbn {__version__}')
    parser.add_argument('-v', '--verbose', action='store_true', help='log at DEBUG level')
    subparsers = parser.add_subparsers(title='commands', dest='command', metavar='COMMAND')
    entry_points = sorted(metadata.entry_points(group='vbn.commands'), key=lambda e: e.name)
    seen: set[str] = set()
    for entry_point in entry_points:
        if entry_point.name in seen:  # the same package found twice on sys.path
            continue
        seen.add(entry_point.name)
        register = entry_point.load()
        register(subparsers)
    return parser


def run_registered(register: Callable[[Any], None], argv: Sequence[str],
                   output: str | Path | None = None, append: bool = False) -> int:
    """Run one command from its imported ``register`` function, as ``vbn`` would.

    The benchmarks and the demo call the builder's, the renderer's and the localizer's
    commands this way: the import names the package they stand on (so the package rules
    see it), and the command parses, reports and fails exactly as on the command line.

    Args:
        register: The command module's ``register(subparsers)``.
        argv: The command's name and its arguments, e.g. ``['build', BAG, '--db', DB]``.
        output: A file to take everything the command prints (its stdout and stderr, and
            its worker processes'), as a shell's ``> FILE 2>&1`` would; ``None`` keeps
            this process's.
        append: Add to ``output`` (``>> FILE 2>&1``) instead of replacing it.

    Returns:
        The exit code: 0, 2 for a ``VbnError`` or an ``OSError`` (its line printed as by
        ``vbn``), or what the command returned.
    """
    parser = argparse.ArgumentParser(prog='vbn')
    parser.add_argument('-v', '--verbose', action='store_true')
    register(parser.add_subparsers(dest='command', metavar='COMMAND'))
    with _redirected(output, append):
        try:
            args = parser.parse_args(list(argv))
        except SystemExit as exit_:  # argparse's usage error
            return int(exit_.code or 0)
        return _run_command(parser, args)


@contextmanager
def _redirected(output: str | Path | None, append: bool) -> Iterator[None]:
    """Point file descriptors 1 and 2, and ``sys.stdout`` and ``sys.stderr``, at ``output``.

    The descriptors take what worker processes and C libraries print; the Python streams
    what this process prints where they are not the descriptors' (under pytest's capture).
    Nothing happens for ``None``.
    """
    if output is None:
        yield
        return
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    target = os.open(output, os.O_WRONLY | os.O_CREAT | (os.O_APPEND if append else os.O_TRUNC),
                     0o666)
    stream = os.fdopen(os.dup(target), 'a', buffering=1)
    try:
        os.dup2(target, 1)
        os.dup2(target, 2)
        with redirect_stdout(stream), redirect_stderr(stream):
            yield
    finally:
        stream.close()
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, target):
            os.close(fd)


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that a command cleans up as on Ctrl-C."""


def _unwinding() -> None:
    # One signal is enough: the command is unwinding, a second one (Ctrl-C twice, or
    # a launcher's SIGINT then SIGTERM) must not cut short the termination of its
    # workers or the removal of its temporary files.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def _on_sigint(signum: int, frame: object) -> None:
    _unwinding()
    raise KeyboardInterrupt


def _on_sigterm(signum: int, frame: object) -> None:
    _unwinding()
    raise Terminated()


def _interruptible() -> None:
    """Let SIGINT and SIGTERM stop any command cleanly, however it was started.

    A command started in the background of a script inherits SIGINT ignored (POSIX
    shells do that without job control), and Python then never raises
    ``KeyboardInterrupt``: ``vbn build`` ran to its end and replaced the database. Both
    signals now unwind the command (workers terminated, temporary files removed, the
    previous output untouched) and end it with one line.
    """
    signal.signal(signal.SIGINT, _on_sigint)
    signal.signal(signal.SIGTERM, _on_sigterm)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``vbn`` and return its exit code.

    A ``VbnError`` or an ``OSError`` (missing file, permission) becomes one line on
    stderr and exit code 2; a closed output pipe ends quietly; Ctrl-C (SIGINT) is
    ``vbn COMMAND: interrupted`` and exit 130, SIGTERM ``terminated`` and exit 143.
    """
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    _interruptible()
    try:
        return _run(argv)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _run(argv: Sequence[str] | None) -> int:
    command = 'vbn'
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        command = f'vbn {args.command}' if getattr(args, 'command', None) else 'vbn'
        return _run_command(parser, args)
    except KeyboardInterrupt:
        print(f'{command}: interrupted', file=sys.stderr)
        return 130
    except Terminated:
        print(f'{command}: terminated', file=sys.stderr)
        return 143


def _run_command(parser: argparse.ArgumentParser, args: argparse.Namespace) -> int:
    logging.basicConfig(
        level=logging.DEBUG if args.verbose else logging.INFO,
        format='%(levelname)s %(name)s: %(message)s',
    )
    if not getattr(args, 'func', None):
        parser.print_help()
        return 0
    try:
        return int(args.func(args) or 0)
    except VbnError as error:
        print(f'vbn {args.command}: error: {error}', file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader of our output went away (``vbn bag-info BAG | head``): stop quietly.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as error:
        print(f'vbn {args.command}: error: {error}', file=sys.stderr)
        return 2


if __name__ == '__main__':
    sys.exit(main())
