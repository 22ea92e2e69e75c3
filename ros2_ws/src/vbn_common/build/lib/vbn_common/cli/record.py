"""``vbn record --topics ... --out BAGDIR``: record topics of any type into an MCAP bag."""
from __future__ import annotations

import argparse

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``record`` subcommand."""
    parser = subparsers.add_parser(
        'record', help='record topics of any type as raw CDR into an MCAP bag',
        description='Subscribe to the given topics as soon as they have publishers (types '
                    'from the graph, QoS adapted to the publishers) and write every message, '
                    'serialized as received, into a rosbag2 MCAP bag (zstd chunks). Ctrl-C '
                    '(SIGINT), SIGTERM or --duration stop it; the bag is closed and valid.')
    parser.add_argument('--topics', nargs='+', required=True, metavar='TOPIC',
                        help='topics to record')
    parser.add_argument('--out', '-o', required=True, metavar='BAGDIR',
                        help='bag directory to create (must not exist)')
    parser.add_argument('--duration', type=float, default=None, metavar='S',
                        help='stop after S seconds (default: until Ctrl-C)')
    parser.add_argument('--compression', choices=('zstd', 'none'), default='zstd',
                        help='MCAP chunk compression (default zstd)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Record until stopped; return 0."""
    import threading

    from vbn_common.bags import BagWriter
    from vbn_common.errors import VbnCommonError
    from vbn_common.ros_tools.record import Recorder
    from vbn_common.ros_tools.session import on_stop_signals, ros_node

    if args.duration is not None and not args.duration > 0:
        raise VbnCommonError(f'--duration must be positive, got {args.duration}')
    stop = threading.Event()
    # Signals only set the flag: the recorder then takes what arrived and closes the bag.
    with on_stop_signals(lambda _signum: stop.set()), \
            ros_node('vbn_record') as (node, executor):
        writer = BagWriter(args.out, compression=args.compression, atomic=False).open()
        try:
            recorder = Recorder(node, writer, args.topics, stop_event=stop,
                                announce=lambda line: print(line, flush=True))
            print(f'recording into {args.out}; waiting for {", ".join(args.topics)}',
                  flush=True)
            recorder.spin(executor, args.duration)
        finally:
            writer.close()
        counts = ', '.join(f'{t}: {n}' for t, n in recorder.counts.items()) or 'no topics'
        print(f'wrote {recorder.message_count} messages to {args.out} ({counts})', flush=True)
    return 0
