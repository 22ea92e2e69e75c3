"""``vbn echo TOPIC``: print a topic's messages as YAML, like ``ros2 topic echo``."""
from __future__ import annotations

import argparse

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``echo`` subcommand."""
    parser = subparsers.add_parser(
        'echo', help="print a topic's messages as YAML (like ros2 topic echo)",
        description='Subscribe to TOPIC (type from the graph, QoS adapted to the publishers) '
                    'and print each message as YAML followed by ---, as ros2 topic echo does. '
                    'Arrays and strings longer than --truncate-length (default 128) are cut '
                    "with a '...' element.")
    parser.add_argument('topic', metavar='TOPIC', help='topic name, e.g. /ground_truth/pose')
    parser.add_argument('--once', action='store_true', help='print one message and exit')
    parser.add_argument('--count', type=int, default=None, metavar='N',
                        help='print N messages and exit')
    parser.add_argument('--timeout', type=float, default=None, metavar='S',
                        help='fail if no publisher appears or the messages asked for do not '
                             'arrive within S seconds (default: wait, saying so once on stderr)')
    parser.add_argument('--type', dest='msgtype', default=None, metavar='TYPE',
                        help='message type (default: from the graph)')
    parser.add_argument('--truncate-length', type=int, default=128, metavar='N',
                        help='cut arrays, bytes and strings longer than N (default 128)')
    parser.add_argument('--full-length', action='store_true',
                        help='print arrays and strings in full')
    parser.add_argument('--no-arr', action='store_true', help='print arrays as type and length')
    parser.add_argument('--no-str', action='store_true', help='print strings as their length')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Echo until the count is reached or Ctrl-C; return 0."""
    import sys

    from vbn_common.errors import VbnCommonError
    from vbn_common.ros_tools.echo import EchoOptions, echo_topic
    from vbn_common.ros_tools.session import (
        on_stop_signals,
        raise_keyboard_interrupt,
        ros_node,
    )

    count = 1 if args.once else args.count
    if count is not None and count < 1:
        raise VbnCommonError(f'--count must be at least 1, got {count}')
    options = EchoOptions(
        count=count, timeout_s=args.timeout, msgtype=args.msgtype,
        truncate_length=None if args.full_length else args.truncate_length,
        no_arr=args.no_arr, no_str=args.no_str)

    def write(text: str) -> None:
        sys.stdout.write(text)
        sys.stdout.flush()

    with on_stop_signals(raise_keyboard_interrupt), ros_node('vbn_echo') as (node, executor):
        try:
            echo_topic(node, executor, args.topic, options, write,
                       notify=lambda line: print(line, file=sys.stderr, flush=True))
        except KeyboardInterrupt:
            pass
    return 0
