r"""``vbn bench-integrity``: never a confident wrong pose, in worlds that changed.

Example::

    vbn bench-integrity --out out/bench_integrity --scenes room,hall --seeds 1,2

Per scene (``room``, ``hall``: an L-shaped hall drawn per seed, ``floor``: the 25 cm
floor, long) the database is built from its exploration as it was (``bags/`` for the
room, else rendered into ``--out``), then each run of
:data:`vbn_bench.localization.worlds.RUNS` is rendered (a path per seed; the world
unchanged, changed, dim, bright, with people, kidnapped, with bad odometry at 10 and
2 Hz; and the changed run again
against the database updated by ``vbn db-update`` with an exploration of the changed
world) and localized in this process with no initial pose. Per run it prints frames
posed, translation median and p95, poses more than 50 cm off, the share of poses within
3 sigma of their covariance (position ellipse and heading), start-up and recovery
frames (:mod:`vbn_bench.localization.integrity`), against the targets: no
pose 50 cm off, 99 % within 3 sigma over all runs, start-up and recovery within 3
frames, in the changed worlds 95 % posed and p95 5 cm, and after the update the
unchanged run's figures (within 1.5x) or, where the changed run is harder, those of a
database built afresh from the update's exploration on the same run (within 1.2x;
printed beside the updated run). Writes ``results.json``; exits 0 when every
target is met, 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import Any

__all__ = ['register', 'run']


def register(subparsers: Any) -> None:
    """Add the ``bench-integrity`` subcommand."""
    parser = subparsers.add_parser(
        'bench-integrity', help='integrity of the poses (within 3 sigma, none 50 cm off), '
                                'start-up and recovery, in worlds that changed',
        description="Build each scene's database from its exploration, render runs on "
                    'other days (unchanged, changed, dim, bright, with people, kidnapped, '
                    'with wheel slip and odometry dropouts at 10 and 2 Hz), '
                    'the changed run against the database updated by vbn db-update, '
                    'and localize them; print the integrity figures against the targets.')
    parser.add_argument('--out', default='out/bench_integrity', help='output directory')
    parser.add_argument('--scenes', default='room,hall',
                        help='comma-separated: room, hall, floor (default room,hall)')
    parser.add_argument('--seeds', default='1,2', help='comma-separated seeds (default 1,2)')
    parser.add_argument('--runs', default=None,
                        help='comma-separated subset of unchanged, changed, dim, bright, '
                             'people, kidnapped, updated, faults, faults_2hz (default all)')
    parser.add_argument('--set', dest='settings', action='append', default=[],
                        metavar='NAME=VALUE', help='localizer setting (repeatable)')
    parser.set_defaults(func=run)


def _vbn(argv: list[str], log: Path) -> None:
    from vbn_bench.commands import run_command

    print(f'$ vbn {" ".join(argv)}', flush=True)
    with log.open('a') as stream:
        stream.write(f'\n$ vbn {" ".join(argv)}\n')
    run_command(argv, log, isolated=True)


def _scene_arg(scene: str, seed: int, out: Path) -> str:
    """Return ``--scene``'s argument: a shipped name, or the hall's JSON written here."""
    if scene != 'hall':
        return scene
    from vbn_bench.localization.worlds import hall_scene
    from vbn_common.jsonio import write_json_atomic

    path = out / f'hall{seed}.json'
    if not path.exists():
        write_json_atomic(hall_scene(seed), path, indent=1)
    return str(path)


def _key(scene: str, seed: int) -> str:
    """Return the name of a scene's files: the hall is drawn per seed, the others shipped."""
    return f'hall{seed}' if scene == 'hall' else scene


def _database(scene: str, seed: int, out: Path, log: Path) -> Path:
    """Return the scene's database, rendering its exploration and building it if missing."""
    key = _key(scene, seed)
    db = out / f'{key}.db'
    if db.exists():
        return db
    shipped = {'room': Path('bags/room_exploration')}.get(scene)
    bag = shipped if shipped is not None and shipped.exists() else \
        out / 'bags' / f'{key}_exploration'
    if not bag.exists():
        bag.parent.mkdir(parents=True, exist_ok=True)
        _vbn(['render', '--scene', _scene_arg(scene, seed, out), '--kind', 'exploration',
              '--compressed', '--out', str(bag)], log)
    _vbn(['build', str(bag), '--db', str(db), '--quiet'], log)
    return db


def _reexplored(scene: str, seed: int, out: Path, log: Path) -> Path:
    """Return the changed world's exploration bag (rendered if missing)."""
    from vbn_bench.localization.worlds import reexplore_argv

    key = _key(scene, seed)
    bag = out / 'bags' / f'{key}_reexplored_s{seed}'
    if not bag.exists():
        bag.parent.mkdir(parents=True, exist_ok=True)
        argv = reexplore_argv(_scene_arg(scene, seed, out), seed, scene == 'room')
        _vbn([*argv, '--out', str(bag)], log)
    return bag


def _updated_database(scene: str, seed: int, db: Path, out: Path, log: Path) -> Path:
    """Return ``db`` updated with an exploration of the changed world."""
    key = _key(scene, seed)
    updated = out / f'{key}_updated_s{seed}.db'
    if not updated.exists():
        _vbn(['db-update', str(db), str(_reexplored(scene, seed, out, log)), '--out',
              str(updated), '--json', str(updated.with_suffix('.json'))], log)
    return updated


def _rebuilt_database(scene: str, seed: int, out: Path, log: Path) -> Path:
    """Return a database built afresh from the changed world's exploration alone."""
    key = _key(scene, seed)
    rebuilt = out / f'{key}_rebuilt_s{seed}.db'
    if not rebuilt.exists():
        _vbn(['build', str(_reexplored(scene, seed, out, log)), '--db', str(rebuilt),
              '--quiet'], log)
    return rebuilt


def _localize(db: Path, bag: Path, settings: list[str]) -> Any:
    import numpy as np

    from landmark_db.database.store import open_database
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.localizer import Localizer
    from vbn_bench.localization.integrity import integrity_figures
    from vbn_bench.localization.offline import localize_run
    from vbn_bench.localization.pose_bags import read_run_bag
    from vbn_common.cli.assignments import parse_assignments

    run = read_run_bag(bag)
    config = LocalizerConfig().with_values(parse_assignments(settings))
    result = localize_run(Localizer(open_database(db), config), run)
    poses = np.array([e.pose if e.pose is not None else np.full(3, np.nan)
                      for e in result.estimates])
    cov = np.array([e.covariance if e.covariance is not None else np.full((3, 3), np.nan)
                    for e in result.estimates])
    return integrity_figures(run.stamps_ns, poses, cov, run.truth_stamps_ns, run.truth_poses)


def _failures(figures: dict[str, Any], goals: dict[str, float]) -> list[str]:
    bad = []
    for key, goal in goals.items():
        value = figures[key]
        if key == 'recovery':
            worst = max((math.inf if r is None else r) for r in value) if value else math.inf
            if worst > goal:
                bad.append(f'recovery {worst} > {goal:g} frames')
        elif key == 'startup_frames':
            if value is None or value > goal:
                bad.append(f'start-up {value} > {goal:g} frames')
        elif key in ('posed',):
            if not value >= goal:
                bad.append(f'{key} {value:.3f} < {goal:g}')
        elif not value <= goal:
            bad.append(f'{key} {value:.3g} > {goal:g}')
    return bad


def run(args: argparse.Namespace) -> int:
    """Run the benchmark; 0 when every target is met."""
    from landmark_localizer.errors import LocalizerError
    from vbn_bench.localization.integrity import INTEGRITY_SHARE
    from vbn_bench.localization.worlds import RUNS, run_argv, targets, update_failures

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = out / 'bench.log'
    try:
        seeds = [int(s) for s in args.seeds.split(',') if s]
    except ValueError as error:
        raise LocalizerError(f'--seeds takes integers, got {args.seeds!r}') from error
    scenes = [s for s in args.scenes.split(',') if s]
    unknown = set(scenes) - {'room', 'hall', 'floor'}
    runs = RUNS if args.runs is None else tuple(r for r in args.runs.split(',') if r)
    unknown |= set(runs) - set(RUNS)
    if unknown or not scenes or not seeds or not runs:
        raise LocalizerError(f'unknown or no scenes or runs: {sorted(unknown)}')
    rows: list[dict[str, Any]] = []
    for scene in scenes:
        for seed in seeds:
            db = _database(scene, seed, out, log)
            for name in runs:
                run_name = 'changed' if name == 'updated' else name  # the same run
                bag = out / 'bags' / f'{scene}_{run_name}_s{seed}'
                if not bag.exists():
                    bag.parent.mkdir(parents=True, exist_ok=True)
                    argv = run_argv(_scene_arg(scene, seed, out), run_name, seed)
                    _vbn([*argv, '--out', str(bag)], log)
                against = db if name != 'updated' else \
                    _updated_database(scene, seed, db, out, log)
                figures = _localize(against, bag, args.settings).as_dict()
                figures.update(scene=scene, seed=seed, run=name,
                               failures=_failures(figures, targets(name)))
                same = [r for r in rows if (r['scene'], r['seed'], r['run']) ==
                        (scene, seed, 'unchanged')]
                if name == 'updated':
                    rebuilt = _localize(_rebuilt_database(scene, seed, out, log), bag,
                                        args.settings).as_dict()
                    figures['rebuilt'] = {k: rebuilt[k] for k in ('posed', 'median_m', 'p95_m')}
                    if same:
                        figures['failures'] += update_failures(figures, same[0],
                                                               figures['rebuilt'])
                rows.append(figures)
                print(_row(figures), flush=True)
    within = sum(r['within'] * r['poses'] for r in rows) / max(sum(r['poses'] for r in rows), 1)
    summary = {'within_3_sigma_all_runs': within, 'target': INTEGRITY_SHARE,
               'far_all_runs': sum(r['far'] for r in rows),
               'runs_failing': sum(bool(r['failures']) for r in rows)}
    (out / 'results.json').write_text(json.dumps({'runs': rows, 'summary': summary},
                                                 indent=1, default=float))
    print(f'all runs: {100 * within:.2f} % of poses within 3 sigma (target '
          f'{100 * INTEGRITY_SHARE:.0f} %), {summary["far_all_runs"]} poses > 50 cm off, '
          f'{summary["runs_failing"]} of {len(rows)} runs miss a target')
    passed = within >= INTEGRITY_SHARE and summary['runs_failing'] == 0
    print('PASS' if passed else 'FAIL')
    return 0 if passed else 1


def _row(f: dict[str, Any]) -> str:
    recovery = ','.join('-' if r is None else str(r) for r in f['recovery'])
    return (f"{f['scene']:6s} s{f['seed']} {f['run']:10s} posed {100 * f['posed']:5.1f} % "
            f"median {100 * f['median_m']:.2f} p95 {100 * f['p95_m']:.2f} cm, "
            f"> 50 cm {f['far']}, within 3 sigma {100 * f['within']:.1f} % "
            f"(pos {100 * f['within_position']:.1f}, heading {100 * f['within_heading']:.1f})"
            f", start-up {f['startup_frames']}"
            + (f', recovery {recovery}' if f['recovery'] else '')
            + (f" (rebuilt database: posed {100 * f['rebuilt']['posed']:.1f} %, median "
               f"{100 * f['rebuilt']['median_m']:.2f} p95 {100 * f['rebuilt']['p95_m']:.2f} cm)"
               if 'rebuilt' in f else '')
            + (f"  MISS: {'; '.join(f['failures'])}" if f['failures'] else ''))
