"""``vbn localize --db DB BAGDIR --out POSES_BAGDIR``: the localizer core over a bag, offline.

Example::

    vbn localize --db out/room.db bags/room_run --out out/room_run_poses
    evo_ape bag2 out/room_run_poses /ground_truth/pose /localizer/pose

Runs :class:`~landmark_localizer.localizer.Localizer` on every image of the bag as fast
as it can (odometry from ``/odom`` interpolated at each image's stamp), writes
``/localizer/pose``, ``/localizer/pose_with_covariance``, ``/localizer/region`` and a
copy of ``/ground_truth/pose`` into a bag that ``evo_ape bag2`` reads, and prints the
run's figures: frames, poses, availability, region changes by prediction and after a
loss, latency (decoding included) and, with ground truth, the accuracy computed here
and by evo from the written bag. ``--one-core`` measures latency as the targets ask:
BLAS and OpenCV on one thread, the process pinned to one CPU.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import sys
from typing import Any

__all__ = ['register', 'run', 'use_one_core']


def register(subparsers: Any) -> None:
    """Add the ``localize`` subcommand."""
    parser = subparsers.add_parser(
        'localize', help='run the localizer over a bag offline and evaluate it',
        description='Localize every image of a run bag against a landmark database (the '
                    'same core as the localizer node, as fast as it can), write the poses '
                    'and a copy of the ground truth into a bag evo_ape bag2 reads, and '
                    'print availability, switching, latency and accuracy.')
    parser.add_argument('bag', metavar='BAGDIR', help='run bag directory (or .mcap)')
    parser.add_argument('--db', required=True, metavar='DB', help='landmark database')
    parser.add_argument('--out', required=True, metavar='POSES_BAGDIR',
                        help='pose bag to write (must not exist unless --overwrite)')
    parser.add_argument('--overwrite', action='store_true', help='replace --out if it exists')
    parser.add_argument('--set', dest='settings', action='append', default=[],
                        metavar='NAME=VALUE',
                        help='a localizer setting by its parameter name, e.g. min_tracked=6 '
                             '(repeatable; names as in config/localizer.yaml)')
    parser.add_argument('--limit', type=int, default=None, metavar='N',
                        help='localize only the first N images')
    parser.add_argument('--image-topic', default=None,
                        help='image topic (default /camera/image_raw, else .../compressed)')
    parser.add_argument('--one-core', action='store_true',
                        help='one BLAS and OpenCV thread, pinned to one CPU (latency figures)')
    parser.add_argument('--baseline', metavar='EXPLORATION_BAGDIR', default=None,
                        help='localize with the baseline instead: every frame matched '
                             'against every SIFT feature of this exploration bag '
                             '(vbn_bench.localization.baseline; --db gives the SIFT settings)')
    parser.add_argument('--baseline-cache', metavar='FILE.npz', default=None,
                        help="keep the baseline's full feature database in this file")
    parser.add_argument('--peer', metavar='EXPLORATION_BAGDIR', default=None,
                        help='localize with the structure-based peer instead: SIFT tracks of '
                             'this exploration bag triangulated with its poses, every frame '
                             'matched to them and posed by pycolmap '
                             '(vbn_bench.localization.peer; --db gives the SIFT settings)')
    parser.add_argument('--peer-mode', choices=('global', 'tracking'), default='global',
                        help="the peer's matching: every frame against the whole map, or "
                             'near the pose the last one and the odometry predict')
    parser.add_argument('--peer-descriptors', choices=('all', 'one'), default='all',
                        help="the peer's map: every observation's descriptor, or one per "
                             'point (its compact form)')
    parser.add_argument('--peer-cache', metavar='FILE.npz', default=None,
                        help="keep the peer's map in this file")
    parser.add_argument('--no-evo', action='store_true', help='skip the check by evo_ape')
    parser.add_argument('--json', metavar='FILE', default=None,
                        help='write the figures as JSON into FILE')
    parser.add_argument('--quiet', action='store_true', help='no progress line')
    parser.set_defaults(func=run)


def use_one_core() -> str:
    """One BLAS and OpenCV thread, and this process pinned to one CPU where possible.

    OpenBLAS reads its thread count when numpy is first imported: call this before, or
    set ``OPENBLAS_NUM_THREADS=1`` in the environment (``vbn bench-localize`` does for
    its children). Processes started afterwards inherit the pinning.

    Returns:
        What was done, for the summary.
    """
    for name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
        os.environ.setdefault(name, '1')
    from landmark_localizer.node_support import one_thread_per_library

    one_thread_per_library()   # as the node does (and OpenBLAS already loaded, too)
    done = [f'OPENBLAS_NUM_THREADS={os.environ["OPENBLAS_NUM_THREADS"]}',
            'cv2.setNumThreads(1)']
    if hasattr(os, 'sched_setaffinity'):
        cpus = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpus[-1]})
        done.append(f'pinned to CPU {cpus[-1]}')
    return ', '.join(done)


def _progress(quiet: bool):  # noqa: ANN202 - a small closure
    if quiet or not sys.stderr.isatty():
        return None

    def show(done: int, total: int) -> None:
        end = '\n' if done == total else ''
        print(f'\r[localize] {done}/{total} frames', end=end, file=sys.stderr, flush=True)
    return show


def run(args: argparse.Namespace) -> int:
    """Localize the bag, write the pose bag, print the figures."""
    if args.one_core:  # before numpy is imported: OpenBLAS reads it once
        for name in ('OPENBLAS_NUM_THREADS', 'OMP_NUM_THREADS', 'MKL_NUM_THREADS'):
            os.environ.setdefault(name, '1')
    from landmark_db.database import open_database
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.errors import LocalizerError
    from landmark_localizer.localizer import Localizer
    from vbn_bench.localization.evaluation import evo_ape, format_evaluation
    from vbn_bench.localization.offline import (
        check_run_camera,
        coverage_split,
        evaluate_offline,
        localize_run,
        never_recognised,
    )
    from vbn_bench.localization.pose_bags import read_run_bag, write_pose_bag
    from vbn_common.cli.assignments import parse_assignments

    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise LocalizerError(f'{out} exists already (use --overwrite to replace it)')
    if args.limit is not None and args.limit < 1:
        raise LocalizerError(f'--limit must be >= 1, got {args.limit}')
    config = LocalizerConfig().with_values(parse_assignments(args.settings))
    database = open_database(args.db)
    if args.baseline and args.peer:
        raise LocalizerError('--baseline and --peer are two other localizers: give one')
    run_bag = read_run_bag(args.bag, limit=args.limit, image_topic=args.image_topic)
    if args.peer:
        from vbn_bench.localization.peer import PeerConfig, PeerLocalizer
        from vbn_bench.localization.peer_map import build_peer_map
        from vbn_common.features import SiftConfig

        sift = SiftConfig(**{k: v for k, v in database.info.sift.items()
                             if k in SiftConfig.__dataclass_fields__})
        peer_map = build_peer_map(args.peer, sift, cache=args.peer_cache)
        localizer = PeerLocalizer(
            peer_map, check_run_camera(run_bag, peer_map.camera(), args.peer),
            PeerConfig(mode=args.peer_mode, descriptors=args.peer_descriptors))
        size_bytes = peer_map.nbytes if args.peer_descriptors == 'all' else \
            peer_map.compact_nbytes
    elif args.baseline:
        from vbn_bench.localization.baseline import FullDatabaseLocalizer, build_full_database
        from vbn_common.features import SiftConfig

        sift = SiftConfig(**{k: v for k, v in database.info.sift.items()
                             if k in SiftConfig.__dataclass_fields__})
        full = build_full_database(args.baseline, sift, cache=args.baseline_cache)
        localizer = FullDatabaseLocalizer(full)
        size_bytes = full.nbytes
    else:
        localizer = Localizer(database, config)
        size_bytes = Path(args.db).stat().st_size
        if localizer.tracker.scene.unavailable:
            print(f'vbn localize: warning: {args.db}: {localizer.tracker.scene.unavailable}',
                  file=sys.stderr)
    if not (args.baseline or args.peer):
        localizer.index.frame_camera = check_run_camera(run_bag, localizer.index.camera,
                                                        args.db)
    pinned = use_one_core() if args.one_core else ''  # after the baseline's SIFT pool
    result = localize_run(localizer, run_bag, progress=_progress(args.quiet))
    n_poses = write_pose_bag(out, result.records(), run_bag.truth_messages,
                             overwrite=args.overwrite)
    if never_recognised(result):
        print(f'vbn localize: warning: no region of {args.db} was recognised in any of the '
              f'{run_bag.n_frames} frames of {args.bag}: is it a run of the place the '
              'database was built from?', file=sys.stderr)
    stats = getattr(localizer, 'stats', None)
    evaluation = evaluate_offline(result, run_bag, stats.falls_to_lost if stats else None)
    if run_bag.truth_messages and n_poses and not args.no_evo:
        from dataclasses import replace

        evaluation = replace(evaluation, evo=evo_ape(out))
    against = f'the full feature database of {args.baseline}' if args.baseline else \
        f"the peer's map of {args.peer} ({args.peer_mode})" if args.peer else args.db
    title = (f'vbn localize: {args.bag} against {against} ({size_bytes / 1e6:.2f} MB) -> {out} '
             f'({result.wall_seconds:.1f} s, {run_bag.n_frames / result.wall_seconds:.1f} '
             f'frames/s{"; " + pinned if pinned else ""})')
    print(format_evaluation(evaluation, title))
    events = dict(sorted(stats.events.items())) if stats else {}
    if stats:
        print(f'  events            {events}')
    health = getattr(localizer, 'health', None)   # the baseline and the peer have none
    stale = health.stale_regions() if health is not None else []
    summary = health.summary() if health is not None else None
    if summary is not None:
        print(f'  stale regions     {len(stale)} of {len(summary)} tracked' + (
            ': ' + ', '.join(f'{r} ({summary[r]["failing"]} of {summary[r]["landmark"]} '
                             'landmark features failing)' for r in stale) if stale else ''))
    split = {} if args.baseline or args.peer else coverage_split(result, run_bag, localizer.index)
    for name, part in split.items():
        if part['frames']:
            print(f'  {name + " regions":17s} {part["frames"]} frames, availability '
                  f'{100 * part["availability"]:.1f} %, translation median '
                  f'{100 * part["translation_median_m"]:.2f} cm, p95 '
                  f'{100 * part["translation_p95_m"]:.2f} cm')
    if args.json:
        figures = evaluation.as_dict()
        figures.update(bag=str(args.bag), db=str(args.db), baseline=args.baseline,
                       peer=args.peer and {'exploration': args.peer, 'mode': args.peer_mode,
                                           'descriptors': args.peer_descriptors,
                                           'map_bytes': peer_map.nbytes,
                                           'compact_bytes': peer_map.compact_nbytes,
                                           'points': len(peer_map.points)},
                       size_bytes=size_bytes, out=str(out), one_core=pinned,
                       wall_seconds=result.wall_seconds, events=events,
                       votes=stats.votes if stats else None, settings=config.as_dict(),
                       coverage=split, stale_regions=stale,
                       region_health=summary,
                       frames_detail=_frames_detail(result.estimates))
        Path(args.json).write_text(json.dumps(figures, indent=1, default=_json_default))
    return 0


def _frames_detail(estimates: list) -> dict[str, list]:
    """Per-frame state, region, event and step time (to say which frames fell short)."""
    return {'stamp_ns': [e.stamp_ns for e in estimates],
            'state': [e.state for e in estimates],
            'region': [e.region for e in estimates],
            'event': [e.event for e in estimates],
            'has_pose': [e.pose is not None for e in estimates],
            'seconds': [round(e.seconds, 6) for e in estimates]}


def _json_default(value: Any) -> Any:
    import math

    if isinstance(value, float) and not math.isfinite(value):
        return None
    if hasattr(value, 'tolist'):
        return value.tolist()
    return str(value)
