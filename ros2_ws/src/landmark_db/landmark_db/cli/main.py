"""``vbn``: the view-based navigation command line.

Subcommands are contributed by the project's packages through the ``vbn.commands``
entry-point group. Each entry point names a ``register(subparsers)`` function that
adds one subparser and sets its ``func`` default to a ``run(args) -> int``
callable. Command modules keep heavy imports inside ``run`` so that ``vbn --help``
stays fast.
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence
from importlib import metadata
import logging
import os
import signal
import sys

from landmark_db import __version__
from landmark_db.errors import VbnError

__all__ = ['build_parser', 'main']

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
