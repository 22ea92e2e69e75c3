"""``vbn bench-estimate``: image poses from images and odometry against the truth.

Example::

    vbn bench-estimate --out out/bench_estimate
    vbn bench-estimate --out out/bench_estimate --scenes room,floor --drifts 1,3 --seeds 0,1
    vbn bench-estimate --out out/bench_estimate --cameras pinhole --spacing 0.5

For each scene, drift and seed: renders a driven exploration (``vbn render --kind
exploration --odometry``, kept in ``OUT/bags``), estimates its poses (``vbn
estimate-poses --frame truth``) and prints the odometry's, the thesis's and the refined
errors after an SE(2) alignment with the targets of point 5 (median 1 cm, max 5 cm,
heading median 0.2 deg), the wheels' calibration by the images' turns and the scale error
left (the calibrated odometry's). For the panoramic room
it then builds databases from the estimated poses, from the estimated poses scaled by a
known distance (``--known-distance``: the two images farthest apart, their true distance
to the millimetre, as a user measures it) and from the same bag's ground truth, and
localizes ``bags/room_run`` with each (``vbn localize --one-core``): the estimated
database's median and p95 against 1.5 times the ground truth's. ``--cameras pinhole``
explores with a pinhole camera at 8 headings per place (``fisheye``: 4). Everything goes
into ``OUT/summary.json``.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

__all__ = ['register', 'run']

#: Point 5's targets: refined image positions (metres), heading (degrees), the database.
TARGETS = {'position_median': 0.01, 'position_max': 0.05, 'heading_median_deg': 0.2,
           'localize_ratio': 1.5}

#: Headings per exploration position of each camera (a pinhole sees 90 degrees).
HEADINGS = {'panoramic': 1, 'pinhole': 8, 'fisheye': 4}


def register(subparsers: Any) -> None:
    """Add the ``bench-estimate`` subcommand."""
    parser = subparsers.add_parser(
        'bench-estimate', help='estimated exploration poses against the truth',
        description='Render driven explorations, estimate their poses from the images and '
                    'the odometry, judge them against the ground truth, and localize '
                    'bags/room_run with databases built from estimated and true poses.')
    parser.add_argument('--out', required=True, metavar='DIR', help='output folder')
    parser.add_argument('--scenes', default='room', help='scenes, comma separated (room)')
    parser.add_argument('--drifts', default='1,3', help='odometry drift scales (1,3)')
    parser.add_argument('--seeds', default='0', help='render seeds (0)')
    parser.add_argument('--cameras', default='panoramic',
                        help='cameras, comma separated: panoramic, pinhole (8 headings), '
                             'fisheye (4 headings) (panoramic)')
    parser.add_argument('--spacing', type=float, default=0.25, help='grid spacing, m (0.25)')
    parser.add_argument('--radius', type=float, default=None,
                        help='estimate-poses --radius (default: its own)')
    parser.add_argument('--run', default='bags/room_run',
                        help='run localized with the room databases ("" to skip)')
    parser.set_defaults(func=run)


def _vbn(*argv: str, log: Path) -> None:
    from vbn_bench.commands import run_command

    run_command(argv, log, append=False, isolated=True)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark, print the table, write ``summary.json``; 0 when every target holds."""
    from vbn_common.atomic import write_text_atomic
    from visibility_builder.errors import VisibilityBuilderError

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / 'bags').mkdir(exist_ok=True)
    scenes = [s for s in args.scenes.split(',') if s]
    try:
        drifts = [float(d) for d in args.drifts.split(',') if d]
        seeds = [int(s) for s in args.seeds.split(',') if s]
    except ValueError as error:
        raise VisibilityBuilderError(f'--drifts and --seeds take numbers: {error}') from error
    rows: list[dict[str, Any]] = []
    cameras = [c for c in args.cameras.split(',') if c]
    unknown = sorted(set(cameras) - set(HEADINGS))
    if unknown:
        raise VisibilityBuilderError(f'--cameras: unknown {unknown} (expected '
                                     f'{", ".join(HEADINGS)})')
    for scene in scenes:
        for camera in cameras:
            for drift in drifts:
                for seed in seeds:
                    rows.append(_one(out, scene, camera, drift, seed, args))
    lines = ['| scene | camera | drift | seed | odometry median / max | thesis median / max | '
             'refined median / max, heading | pieces (the largest alone: images, median / '
             'max) | wheels calibrated | scale error | estimate time | room_run, DB of estimated '
             'poses: median / p95 (ratio) | ... scaled by a known distance | DB of true poses |',
             '|' + '---|' * 14]
    passed = True
    for r in rows:
        odo, thesis, res = r['odometry'], r['thesis'], r['result']
        loc = r.get('localize') or {}
        ratio = loc.get('ratio', float('nan'))

        def db(key: str, loc: dict[str, Any] = loc) -> str:
            if key not in loc:
                return '-'
            ratio = f" ({loc[key + '_ratio']:.2f})" if key + '_ratio' in loc else ''
            return f'{100 * loc[key][0]:.2f} / {100 * loc[key][1]:.2f} cm{ratio}'

        lines.append(
            f"| {r['scene']} | {r.get('camera', 'panoramic')} | {r['drift']:g} | {r['seed']} | "
            f"{100 * odo['position_median']:.2f} / {100 * odo['position_max']:.1f} cm | "
            f"{100 * thesis['position_median']:.2f} / {100 * thesis['position_max']:.2f} cm | "
            f"{100 * res['position_median']:.2f} / {100 * res['position_max']:.2f} cm, "
            f"{res['heading_median_deg']:.3f} deg | {_pieces(r)} | {_wheels(r)} | "
            f"{100 * (r.get('result_scale', float('nan')) - 1):+.3f} % | "
            f"{sum(r['times'].values()):.0f} s | {db('estimated')} | {db('known')} | "
            f"{db('truth')} |")
        ok = (res['position_median'] <= TARGETS['position_median']
              and res['position_max'] <= TARGETS['position_max']
              and res['heading_median_deg'] <= TARGETS['heading_median_deg']
              and (not loc or ratio <= TARGETS['localize_ratio']))
        r['pass'] = ok
        passed &= ok
    print('\n'.join(lines))
    print(f"targets: refined median <= {100 * TARGETS['position_median']:g} cm, max <= "
          f"{100 * TARGETS['position_max']:g} cm, heading median <= "
          f"{TARGETS['heading_median_deg']:g} deg; estimated database within "
          f"{TARGETS['localize_ratio']:g} x the ground truth's median and p95: "
          + ('PASS' if passed else 'FAIL'))
    print('scale error: the similarity scale that maps the refined positions onto the truth, '
          "minus one (the odometry sets it, its wheels calibrated by the images' turns: "
          'their distances times p, with its standard deviation; a known distance between '
          'the two images farthest apart, to the millimetre, replaces it in the last '
          'database)')
    write_text_atomic(out / 'summary.json', json.dumps(rows, indent=2, default=float))
    return 0 if passed else 1


def _wheels(row: dict[str, Any]) -> str:
    """Return the wheels' calibration (``estimation/scale.py``): x p +- std, or why not."""
    wheels = row.get('wheels')
    if not wheels:
        return '-'
    figure = (f"x {wheels['distance_scale']:.4f} +- {100 * wheels['distance_scale_std']:.3f} "
              '%')
    return figure if wheels['applied'] else f'no ({figure})'


def _pieces(row: dict[str, Any]) -> str:
    """Return the count of view-graph pieces and the largest one's own figures."""
    count = row.get('pieces', 1)
    piece = row.get('largest_piece')
    if piece is None:
        return str(count)
    return (f"{count} ({piece['count']}: {100 * piece['position_median']:.2f} / "
            f"{100 * piece['position_max']:.2f} cm)")


def _one(out: Path, scene: str, camera: str, drift: float, seed: int,
         args: argparse.Namespace) -> dict[str, Any]:
    lens = '' if camera == 'panoramic' else f'_{camera}'
    name = f'{Path(scene).stem}{lens}_s{args.spacing:g}_d{drift:g}_seed{seed}'
    bag = out / 'bags' / name
    if not bag.exists():
        headings = ['--headings', str(HEADINGS[camera])] if HEADINGS[camera] > 1 else []
        _vbn('render', '--scene', scene, '--kind', 'exploration', '--camera', camera,
             *headings, '--spacing', str(args.spacing), '--odometry', '--drift', str(drift),
             '--seed', str(seed), '--compressed', '--out', str(bag),
             log=out / f'{name}_render.log')
    estimated = out / f'{name}_estimated'
    figures = out / f'{name}_estimate.json'
    if not figures.exists() or not estimated.exists():
        if estimated.exists():
            import shutil

            shutil.rmtree(estimated)
        extra = ['--radius', str(args.radius)] if args.radius else []
        _vbn('estimate-poses', str(bag), '--out', str(estimated), '--frame', 'truth',
             '--json', str(figures), '--quiet', *extra, log=out / f'{name}_estimate.log')
    row = {'scene': scene, 'camera': camera, 'drift': drift, 'seed': seed, 'bag': str(bag),
           **json.loads(figures.read_text())}
    print(f'{name}: refined {100 * row["result"]["position_median"]:.2f} cm median',
          flush=True)
    if Path(scene).stem == 'room' and camera == 'panoramic' and args.run:
        known = out / f'{name}_known'
        if not known.exists():
            first, second, metres = _farthest(bag)
            _vbn('estimate-poses', str(bag), '--out', str(known), '--frame', 'truth',
                 '--known-distance', str(first), str(second), f'{metres:.3f}', '--quiet',
                 log=out / f'{name}_known.log')
        row['localize'] = _localize(out, name, bag, {'estimated': estimated, 'known': known},
                                    Path(args.run))
    return row


def _farthest(bag: Path) -> tuple[int, int, float]:
    """Return the two images farthest apart and their true distance to the millimetre.

    What a user measures with a laser distance meter between two marked places; the
    benchmark reads it from the ground truth.
    """
    import numpy as np

    from vbn_common.exploration import ReadConfig, read_exploration

    truth = read_exploration(bag, ReadConfig(pose_source='ground_truth')).base_poses()[:, :2]
    first = int(np.argmax(np.linalg.norm(truth - truth.mean(axis=0), axis=1)))
    second = int(np.argmax(np.linalg.norm(truth - truth[first], axis=1)))
    return first, second, round(float(np.linalg.norm(truth[second] - truth[first])), 3)


def _localize(out: Path, name: str, bag: Path, estimated: dict[str, Path], run_bag: Path
              ) -> dict[str, Any]:
    result: dict[str, Any] = {}
    sources = [('truth', bag, 'read.pose_source=ground_truth')] + [
        (key, path, 'read.pose_source=estimated') for key, path in estimated.items()]
    for key, source, setting in sources:
        db = out / f'{name}_{key}.db'
        if not db.exists():
            _vbn('build', str(source), '--db', str(db), '--set', setting, '--quiet',
                 log=out / f'{name}_{key}_build.log')
        figures = out / f'{name}_{key}_localize.json'
        _vbn('localize', str(run_bag), '--db', str(db), '--out', str(out / f'{name}_{key}_poses'),
             '--overwrite', '--one-core', '--quiet', '--no-evo', '--json', str(figures),
             log=out / f'{name}_{key}_localize.log')
        accuracy = json.loads(figures.read_text())['accuracy']
        result[key] = (accuracy['translation_median_m'], accuracy['translation_p95_m'])
    for key in estimated:
        result[f'{key}_ratio'] = max(result[key][0] / result['truth'][0],
                                     result[key][1] / result['truth'][1])
    result['ratio'] = result['estimated_ratio']
    return result
