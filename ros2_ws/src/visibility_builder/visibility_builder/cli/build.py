"""``vbn build BAGDIR --db DB``: build the landmark database of an exploration bag.

Example::

    vbn build bags/room_exploration --db out/room.db --report out/room_report

Prints a progress bar while SIFT runs, each step's time and counts at the end, and
with ``--report DIR`` writes ``regions.png`` (regions over the floor plan, one colour
per region), ``visibility_sizes.png`` (poses per feature class before and after the
filters, the thesis's Figure 8.7) and ``summary.json`` (every count and time).
"""
from __future__ import annotations

import argparse
from pathlib import Path
import sys
from typing import Any

__all__ = ['register', 'run']


def register(subparsers: Any) -> None:
    """Add the ``build`` subcommand."""
    parser = subparsers.add_parser(
        'build', help='build the landmark database of an exploration bag',
        description='Read an exploration bag (images, camera info, poses from '
                    '/ground_truth/pose or /tf), extract SIFT features, group them into '
                    'correspondence classes (Algorithm 6.3), keep the widely visible ones '
                    '(6.2.2), decompose the poses into regions with k-feature landmarks '
                    '(Chapter 5), pick model views (7.2) and write one SQLite database.')
    parser.add_argument('bag', metavar='BAGDIR', help='exploration bag directory (or .mcap)')
    parser.add_argument('--db', required=True, metavar='DB', help='database file to write')
    parser.add_argument('--k', type=int, default=None, help='features per landmark (8)')
    parser.add_argument('--rho', type=int, default=None, help='overlap radius, graph steps (1)')
    parser.add_argument('--sigma', type=int, default=None,
                        help='a region must serve more than SIGMA poses no other serves (0, '
                             'the default: every k-coverable pose is served)')
    parser.add_argument('--algorithm', default=None,
                        help='decomposition algorithm: A1 A2 A3 B1 B2 C exact best (best)')
    parser.add_argument('--workers', type=int, default=None,
                        help='processes for SIFT and matching (default: every core)')
    parser.add_argument('--set', dest='settings', action='append', default=[],
                        metavar='NAME=VALUE',
                        help='any other setting by its parameter name, e.g. '
                             'classes.gamma=2 or filters.min_poses=12 (repeatable; names '
                             'as in config/builder.yaml)')
    parser.add_argument('--report', metavar='DIR', default=None,
                        help='write figures and summary.json into DIR')
    parser.add_argument('--scene', default=None,
                        help='scene (JSON or shipped name) to draw under the regions')
    parser.add_argument('--quiet', action='store_true', help='no progress bar')
    parser.set_defaults(func=run)


def parse_settings(args: argparse.Namespace) -> dict[str, Any]:
    """Return the ``section.name -> value`` overrides given on the command line."""
    from vbn_common.cli.assignments import parse_assignments

    values = parse_assignments(args.settings)
    for name in ('k', 'rho', 'sigma', 'algorithm'):
        if getattr(args, name) is not None:
            values[f'decomposition.{name}'] = getattr(args, name)
    if args.workers is not None:
        values['workers'] = args.workers
        values['classes.workers'] = args.workers
    return values


def run(args: argparse.Namespace) -> int:
    """Build; print the steps; return 0 on success."""
    from tqdm import tqdm

    from visibility_builder.build import build, config_from_flat
    from visibility_builder.errors import VisibilityBuilderError

    config = config_from_flat(parse_settings(args))
    if args.report:
        report_dir = Path(args.report)
        if not report_dir.parent.is_dir():
            raise VisibilityBuilderError(f'output folder {report_dir.parent} does not exist')
    bar = None

    def on_stage(name: str, detail: str) -> None:
        nonlocal bar
        if bar is not None:
            bar.close()
            bar = None
        print(f'[{name}] {detail}'.rstrip(), file=sys.stderr, flush=True)

    def on_image(count: int) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(desc='SIFT', unit='img', file=sys.stderr, disable=args.quiet,
                       leave=False)
        bar.update(count)

    result = build(args.bag, config, db_path=args.db, on_stage=on_stage, on_image=on_image)
    if bar is not None:
        bar.close()
    report = result.report
    for step, seconds in report.seconds.items():
        counts = ', '.join(f'{k}={_short(v)}' for k, v in report.counts.get(step, {}).items())
        print(f'{step:<12} {seconds:7.2f} s  {counts}')
    total = sum(report.seconds.values())
    db = result.database
    print(f'wrote {args.db}: {len(db.regions)} regions, {db.classes.n_classes} feature '
          f'classes, {db.poses.n_poses} poses, {Path(args.db).stat().st_size / 1e6:.2f} MB '
          f'in {total:.1f} s')
    if args.report:
        from visibility_builder.report import write_report

        write_report(Path(args.report), result, args.scene)
        print(f'report in {args.report}')
    return 0


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.3g}'
    if isinstance(value, dict):
        return '{' + ', '.join(f'{k}: {v}' for k, v in value.items()) + '}'
    return str(value)
