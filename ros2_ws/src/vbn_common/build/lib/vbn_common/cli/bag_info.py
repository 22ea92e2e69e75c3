"""``vbn bag-info BAGDIR``: topics, types, counts, duration, like ``ros2 bag info``."""
from __future__ import annotations

import argparse

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bag-info`` subcommand."""
    parser = subparsers.add_parser(
        'bag-info', help="print a bag's topics, types, counts and duration",
        description='Print what ros2 bag info prints for a rosbag2 MCAP bag: files, size, '
                    'storage, compression, duration, start and end, message count and the '
                    'topics with their types, counts and recorded QoS. A damaged bag is '
                    'described by its readable part, with a warning.')
    parser.add_argument('bag', metavar='BAGDIR', help='bag directory (or a .mcap file)')
    parser.add_argument('--verify', action='store_true',
                        help='read every message and report the counts actually readable')
    parser.add_argument('--json', action='store_true', help='print the summary as JSON')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the summary; return 0."""
    import json

    from vbn_common.bags import format_bag_info, summarize_bag

    summary = summarize_bag(args.bag, verify=args.verify)
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        print(format_bag_info(summary))
    return 0
