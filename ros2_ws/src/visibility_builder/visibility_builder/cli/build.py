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
import json
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
                        help='least newly covered poses of a region (3)')
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
    from landmark_db.cli.assignments import parse_assignments

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
        write_report(Path(args.report), result, args.scene)
        print(f'report in {args.report}')
    return 0


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f'{value:.3g}'
    if isinstance(value, dict):
        return '{' + ', '.join(f'{k}: {v}' for k, v in value.items()) + '}'
    return str(value)


def write_report(folder: Path, result: Any, scene_name: str | None) -> None:
    """Write the figures and ``summary.json`` of a build into ``folder``."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    import numpy as np

    from landmark_db.atomic import write_text_atomic
    from landmark_db.plotting import save_decomposition_figure

    folder.mkdir(exist_ok=True)
    scene = None
    if scene_name:
        from landmark_db.scenes import resolve_scene
        scene = resolve_scene(scene_name)
    db = result.database
    save_decomposition_figure(
        folder / 'regions.png', result.world, [r.poses for r in db.regions], db.info.k,
        db.uncovered, scene=scene,
        title=f'{len(db.regions)} regions, {db.info.algorithm}, k={db.info.k}, '
              f'rho={db.info.rho}, sigma={db.info.sigma}')
    report = result.report
    fig, ax = plt.subplots(figsize=(7, 4))
    before, after = report.visibility_sizes_before, report.visibility_sizes_after
    top = int(max(before.max(initial=1), after.max(initial=1)))
    bins = np.arange(1, top + 2) - 0.5 if top <= 60 else 40
    ax.hist(before[before > 0], bins=bins, alpha=0.5, label=f'after Algorithm 6.3 '
            f'({int((before > 1).sum())} classes seen from 2+ poses)')
    ax.hist(after, bins=bins, alpha=0.6, label=f'after the filters ({after.size} classes, '
            f'median {np.median(after) if after.size else 0:.0f} poses)')
    ax.set_xlabel('poses a feature class is seen from')
    ax.set_ylabel('classes')
    ax.set_yscale('log')
    ax.legend()
    ax.set_title('Feature visibility regions by size (thesis Figure 8.7)')
    fig.tight_layout()
    fig.savefig(folder / 'visibility_sizes.png', dpi=110)
    plt.close(fig)
    summary = report.summary()
    summary['database'] = {'regions': len(db.regions), 'classes': db.classes.n_classes,
                           'poses': db.poses.n_poses, 'k': db.info.k, 'rho': db.info.rho,
                           'sigma': db.info.sigma, 'algorithm': db.info.algorithm,
                           'pose_source': db.info.pose_source}
    write_text_atomic(folder / 'summary.json', json.dumps(summary, indent=2, default=str))
