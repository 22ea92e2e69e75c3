"""``vbn play BAGDIR``: publish a bag's messages with their recorded timing and QoS."""
from __future__ import annotations

import argparse

__all__ = ['register', 'run']


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``play`` subcommand."""
    parser = subparsers.add_parser(
        'play', help='publish a bag over DDS with its recorded timing and QoS',
        description='Publish the serialized messages of a rosbag2 MCAP bag on their recorded '
                    'topics, with their recorded timing and QoS, like ros2 bag play (/tf and '
                    '/tf_static included; /tf_static transient-local as recorded). A topic '
                    'whose message type has no Python package installed is left out with a '
                    'warning.')
    parser.add_argument('bag', metavar='BAGDIR', help='bag directory (or a .mcap file)')
    parser.add_argument('--rate', type=float, default=1.0,
                        help='playback speed factor (default 1.0)')
    parser.add_argument('--loop', action='store_true', help='play again at the end, forever')
    parser.add_argument('--clock', type=float, nargs='?', const=40.0, default=None,
                        metavar='HZ',
                        help='publish /clock (rosgraph_msgs/Clock) at HZ (default 40) for '
                             'nodes with use_sim_time')
    parser.add_argument('--topics', nargs='+', metavar='TOPIC',
                        help='play only these topics')
    parser.add_argument('--start-offset', type=float, default=0.0, metavar='S',
                        help='skip the first S seconds of the bag')
    parser.add_argument('--wait-for-subscribers', action='store_true',
                        help='start only when every topic has a matched subscriber')
    parser.add_argument('--wait-timeout', type=float, default=None, metavar='S',
                        help='with --wait-for-subscribers: give up after S seconds')
    parser.add_argument('--realtime', action='store_true',
                        help='run with real-time (SCHED_FIFO) priority if permitted (root or '
                             'CAP_SYS_NICE): keeps the timing exact on a busy machine')
    parser.add_argument('--stats', action='store_true',
                        help='print the achieved timing (inter-message jitter) at the end')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Play the bag; return 0 (also when interrupted with Ctrl-C)."""
    from vbn_common.bags import open_bag
    from vbn_common.errors import VbnCommonError
    from vbn_common.ros_tools.play import Player, PlayOptions
    from vbn_common.ros_tools.session import (
        on_stop_signals,
        raise_keyboard_interrupt,
        ros_node,
    )

    if args.realtime:
        _set_realtime_priority()
    options = PlayOptions(
        rate=args.rate, loop=args.loop, clock_hz=args.clock,
        topics=tuple(args.topics) if args.topics else None,
        start_offset_s=args.start_offset, wait_for_subscribers=args.wait_for_subscribers,
        wait_timeout_s=args.wait_timeout)
    with open_bag(args.bag) as reader, on_stop_signals(raise_keyboard_interrupt), \
            ros_node('vbn_play') as (node, executor):
        player = Player(node, reader, options)
        try:
            if options.wait_for_subscribers:
                print(f'waiting for subscribers on {", ".join(player.publishers)}', flush=True)
                if not player.wait_for_subscribers(executor):
                    raise VbnCommonError(
                        f'no subscriber on {", ".join(player.unmatched_topics())} within '
                        f'{options.wait_timeout_s or 0:g} s')
                print('all publishers matched', flush=True)
            print(f'playing {args.bag}: {", ".join(player.publishers)}', flush=True)
            stats = player.play()
        except KeyboardInterrupt:
            player.stop()
            print(f'interrupted after {player.stats.published} messages', flush=True)
            return 0
        print(f'done: published {stats.published} messages', flush=True)
        if args.stats:
            summary = stats.jitter_summary()
            print('timing: ' + ', '.join(f'{k}={v:.3f}' for k, v in summary.items()), flush=True)
    return 0


def _set_realtime_priority(priority: int = 10) -> None:
    """Switch this process to SCHED_FIFO, or warn that it is not permitted."""
    import logging
    import os

    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (AttributeError, OSError) as error:
        logging.getLogger(__name__).warning(
            'cannot switch to real-time priority (%s); playing with normal priority',
            getattr(error, 'strerror', None) or error)
