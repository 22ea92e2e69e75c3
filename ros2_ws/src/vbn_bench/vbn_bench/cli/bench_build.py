"""``vbn bench-build``: time, memory and size of builds, and the k x rho sweep.

Example::

    make cache-bags                      # the larger bags into cache/
    vbn bench-build --out out/bench_build

For each bag: wall time per step, peak memory of the whole process tree (SIFT workers
included), database size against the full unpruned feature database, regions and
coverage, against the targets. Then a k x rho sweep of the decomposition on the
room bag (thesis Figures 8.8 to 8.15) into ``sweep.png`` and ``results.json``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

__all__ = ['register', 'run']

ROOT_BAGS = ('bags/room_exploration', 'cache/room_exploration_pinhole',
             'cache/floor_exploration')
#: The time targets (seconds) per bag name, and 4 GB of peak memory for the floor.
TARGETS = {'room_exploration': 30.0, 'room_exploration_pinhole': 120.0,
           'floor_exploration': 300.0}


def register(subparsers: Any) -> None:
    """Add the ``bench-build`` subcommand."""
    parser = subparsers.add_parser(
        'bench-build', help='time, memory and size of builds; k x rho sweep',
        description='Build each bag with vbn build in a subprocess and report wall time per '
                    'step, peak memory (process tree), database size against the full '
                    'feature database, regions and coverage; then sweep k and rho on one '
                    'bag (thesis Figures 8.8-8.15).')
    parser.add_argument('--bags', nargs='*', default=None, metavar='BAG',
                        help=f'bags to build (default: those of {", ".join(ROOT_BAGS)} '
                             'that exist)')
    parser.add_argument('--out', required=True, metavar='DIR', help='output folder')
    parser.add_argument('--sweep-bag', default='bags/room_exploration', metavar='BAG',
                        help='bag of the k x rho sweep ("" to skip)')
    parser.add_argument('--ks', default='4,6,8,10', help='k values of the sweep')
    parser.add_argument('--rhos', default='0,1', help='rho values of the sweep')
    parser.add_argument('--set', dest='settings', action='append', default=[],
                        metavar='NAME=VALUE', help='build setting for every build')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark; print the tables; return 0."""
    from vbn_bench.build import run_build
    from vbn_common.atomic import check_output_folder, write_text_atomic
    from visibility_builder.errors import VisibilityBuilderError

    out = Path(args.out)
    check_output_folder(out)
    out.mkdir(exist_ok=True)
    bags = args.bags if args.bags is not None else [b for b in ROOT_BAGS if Path(b).exists()]
    extra = [a for s in args.settings for a in ('--set', s)]
    results: dict[str, Any] = {'builds': [], 'sweep': []}
    print(f'{"bag":<28} {"images":>6} {"total s":>8} {"sift s":>7} {"classes s":>9} '
          f'{"peak MB":>8} {"db MB":>7} {"full MB":>8} {"ratio":>6} {"regions":>7} '
          f'{"coverage":>8}  target')
    for bag in bags:
        record = run_build(bag, out, extra)
        if record.returncode != 0:
            last = record.output.strip().splitlines()[-1:] or ['']
            print(f'{Path(bag).name:<28} failed: {last[0]}')
            results['builds'].append(record.as_dict())
            continue
        counts = record.summary['counts']
        steps = record.summary['seconds']
        target = TARGETS.get(Path(bag).name)
        verdict = ''
        if target is not None:
            ok = record.seconds < target and (Path(bag).name != 'floor_exploration'
                                              or record.peak_bytes < 4 * 2**30)
            verdict = f'{"met" if ok else "MISSED"} (< {target:g} s' + (
                ', < 4 GB)' if Path(bag).name == 'floor_exploration' else ')')
        d = record.as_dict()
        print(f'{Path(bag).name:<28} {counts["features"]["images"]:>6} {record.seconds:>8.1f} '
              f'{steps.get("features", 0):>7.1f} {steps.get("classes", 0):>9.1f} '
              f'{d["peak_mb"]:>8.0f} {d["db_mb"]:>7.2f} {d["full_feature_db_mb"]:>8.1f} '
              f'{d["size_ratio"]:>6.0f} {counts["decompose"]["regions"]:>7} '
              f'{counts["decompose"]["coverage"]:>8.1%}  {verdict}')
        results['builds'].append(d)
    if args.sweep_bag:
        try:
            ks = [int(x) for x in args.ks.split(',')]
            rhos = [int(x) for x in args.rhos.split(',')]
        except ValueError as error:
            raise VisibilityBuilderError(f'--ks and --rhos take integers, got {args.ks!r}, '
                                         f'{args.rhos!r}') from error
        results['sweep'] = _sweep(Path(args.sweep_bag), ks, rhos, out, args.settings)
    write_text_atomic(out / 'results.json', json.dumps(results, indent=2, default=str))
    print(f'results in {out}')
    return 0


def _sweep(bag: Path, ks: list[int], rhos: list[int], out: Path,
           settings: list[str]) -> list[dict[str, Any]]:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from vbn_bench.build import sweep
    from vbn_common.cli.assignments import parse_assignments
    from visibility_builder.build import build, config_from_flat
    from visibility_builder.plotting import draw_decomposition

    config = config_from_flat(parse_assignments(settings))
    result = build(bag, config)
    dc = config.decomposition
    points = sweep(result.world, ks, rhos, dc.algorithm, dc.sigma, dc.seed)
    print(f'\nk x rho sweep on {bag.name} ({dc.algorithm}, sigma={dc.sigma}, '
          f'{result.world.visible.shape[1]} feature classes):')
    print(f'{"k":>3} {"rho":>3} {"regions":>7} {"coverable":>9} {"covered":>8} '
          f'{"coverage":>8} {"mean size":>9}')
    scene = None
    try:
        from landmark_db.scenes import resolve_scene
        scene = resolve_scene(bag.name.split('_')[0])
    except Exception:  # noqa: BLE001 - no shipped scene of that name: draw without walls
        scene = None
    fig, axes = plt.subplots(len(ks), len(rhos), figsize=(5 * len(rhos), 2.9 * len(ks)),
                             squeeze=False)
    rows = []
    for point in points:
        print(f'{point.k:>3} {point.rho:>3} {point.regions:>7} {point.coverable:>9} '
              f'{point.covered:>8} {point.coverage:>8.1%} {point.mean_region_poses:>9.1f}')
        ax = axes[ks.index(point.k)][rhos.index(point.rho)]
        draw_decomposition(ax, result.world, point.decomposition.regions, point.k,
                           point.decomposition.uncovered, scene=scene,
                           title=f'k={point.k}, rho={point.rho}: {point.regions} regions, '
                                 f'{point.coverage:.0%} covered')
        rows.append({'k': point.k, 'rho': point.rho, 'regions': point.regions,
                     'coverable': point.coverable, 'covered': point.covered,
                     'mean_region_poses': round(point.mean_region_poses, 1)})
    fig.tight_layout()
    fig.savefig(out / 'sweep.png', dpi=90)
    plt.close(fig)
    return rows
