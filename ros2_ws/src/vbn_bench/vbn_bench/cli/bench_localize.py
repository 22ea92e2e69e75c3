r"""``vbn bench-localize``: the localizer's figures against its targets, beside the baseline.

Example::

    vbn bench-localize --out out/bench_localize \\
        --build-set classes.tau=120 --build-set classes.symmetry_factor=1

Runs ``vbn localize --one-core`` (one BLAS and OpenCV thread, pinned to one CPU,
decoding included in the latency) as a child process per run, so that every run
starts from a fresh process with ``OPENBLAS_NUM_THREADS=1``:

- ``bags/room_run`` on the room database: accuracy (ours and evo's), availability,
  region changes by prediction, latency in TRACKING and LOST;
- ``bags/room_run_kidnapped``: frames from the teleport to a correct pose;
- ``cache/room_run_effects`` (rendered here if missing, with exposure, blur and noise);
- ``cache/floor_run`` on the floor database (``cache/floor_exploration``): its latency
  targets, TRACKING latency against the room's (it must not grow), and accuracy and
  availability reported (the accuracy targets are the room runs'), also split
  by whether the true position lies in one of the database's regions;
- with ``--cameras pinhole,fisheye``: the lens rooms of ``vbn demo --camera`` (rendered
  into ``--cache`` as ``room_exploration_CAMERA_lens`` and ``room_run_CAMERA_lens`` if
  missing, their databases built into ``--out``), checked against the lens
  cameras' targets (95 % posed, median 2 cm, p95 8 cm, heading median 0.5 deg, no pose
  50 cm off; the pinhole's TRACKING p95 on one core at most 12 ms);
- with ``--seeds S,...``: each room run above (and each lens run) again at every seed
  (:mod:`vbn_bench.localization.seeds`: rendered into ``--cache`` if missing, on the
  same database, the peer beside it), each against the targets and summed up per run;
- with ``--conditions NAME,...`` (or ``all``): the lens cameras' and conditions' rows
  (:mod:`vbn_bench.localization.conditions`: a panorama pitched 2 degrees against the
  level one, a run shaking 0.5 degrees, a run camera 5 cm higher, a 1280 x 960 pinhole
  run on the 640 x 480 database, the 25 cm floor through the lens cameras), their bags
  rendered into ``--cache`` and their databases built into ``--out`` if missing;
- the baseline (:mod:`vbn_bench.localization.baseline`) on ``room_run`` and on the first
  ``--baseline-frames`` frames of ``floor_run``: its figures as ratios to ours, and its
  database's size (all descriptors and keypoints) against ours (the SQLite file);
- the structure-based peer (:mod:`vbn_bench.localization.peer`: SIFT tracks of the
  same exploration triangulated with its poses, every frame's SIFT matched to them and
  posed by pycolmap) on the same runs, both variants on ``room_run`` and the tracking
  one elsewhere (``--skip-peer``: none): side by side with ours, with the ratios, and
  the accuracy targets on each run that has a peer.

Databases that do not exist are built with ``vbn build`` (``--build-set`` passed on).
Latency is wall-clock time per frame (decoding included) and, beside it, the process's
CPU time per frame: on a machine that others share, the pinned CPU runs other work
too, and the CPU time says what a frame costs on one core of its own.

Writes ``results.json`` and ``results.md`` into ``--out`` and prints the table; exits 0
when every target is met, 1 otherwise.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
import time
from typing import Any

__all__ = ['register', 'run']

#: The effects run's seeds (its render settings: ``seeds.SEED_FAMILIES``).
_EFFECTS_SEEDS = ['--seed', '3', '--path-seed', '0']


def register(subparsers: Any) -> None:
    """Add the ``bench-localize`` subcommand."""
    parser = subparsers.add_parser(
        'bench-localize', help="the localizer's accuracy, availability, switching, recovery "
                              'and latency against the targets, beside the baseline',
        description='Run vbn localize on one core over room_run, room_run_kidnapped, an '
                    'effects run and floor_run, and the full-feature-database baseline on '
                    'room_run and part of floor_run; print the figures against the '
                    "targets and the baseline's as ratios to ours.")
    parser.add_argument('--out', default='out/bench_localize', help='output directory')
    parser.add_argument('--room-db', default=None,
                        help='room database (default OUT/room.db, built if missing)')
    parser.add_argument('--floor-db', default=None,
                        help='floor database (default OUT/floor.db, built if missing)')
    parser.add_argument('--build-set', action='append', default=[], metavar='NAME=VALUE',
                        help='vbn build --set for databases built here (repeatable)')
    parser.add_argument('--bags', default='bags', help='folder of the sample bags')
    parser.add_argument('--cache', default='cache',
                        help='folder of floor_exploration, floor_run and the effects run')
    parser.add_argument('--limit', type=int, default=None, metavar='N',
                        help='only the first N frames of each run (a quick look)')
    parser.add_argument('--baseline-frames', type=int, default=150, metavar='N',
                        help='frames of floor_run the baseline localizes (150)')
    parser.add_argument('--skip-floor', action='store_true', help='no floor runs')
    parser.add_argument('--skip-baseline', action='store_true', help='no baseline runs')
    parser.add_argument('--skip-peer', action='store_true',
                        help='no runs of the structure-based peer (pycolmap)')
    parser.add_argument('--cameras', default='', metavar='CAMERA,...',
                        help='also the lens rooms: pinhole, fisheye or both, comma separated '
                             '(rendered into --cache if missing)')
    parser.add_argument('--conditions', default='', metavar='NAME,...',
                        help='also the real-cameras conditions: level, pitch2, vibration, '
                             'height, hires, floor_pinhole, floor_fisheye, comma separated, '
                             'or all (rendered into --cache if missing; each floor one takes '
                             'half an hour or more and 16 GB to render and build)')
    parser.add_argument('--seeds', default='', metavar='SEED,...',
                        help='also every room run (and lens run) rendered again with each of '
                             'these seeds (odometry noise, image effects, path), comma '
                             'separated (rendered into --cache if missing)')
    parser.add_argument('--set', dest='settings', action='append', default=[],
                        metavar='NAME=VALUE', help='localizer setting (repeatable)')
    parser.set_defaults(func=run)


def _call(argv: list[str], log: Path, env: dict[str, str] | None = None) -> int:
    from vbn_bench.commands import run_command

    print(f'$ vbn {" ".join(argv)}', flush=True)
    with log.open('a') as stream:
        stream.write(f'\n$ vbn {" ".join(argv)}\n')
    run_command(argv, log, env=env, isolated=True)
    return 0


def _database(path: Path, bag: Path, settings: list[str], log: Path) -> Path:
    if not path.exists():
        argv = ['build', str(bag), '--db', str(path), '--quiet']
        for item in settings:
            argv += ['--set', item]
        _call(argv, log)
    return path


def _localize(name: str, db: Path, bag: Path, out: Path, log: Path, args: argparse.Namespace,
              baseline: Path | None = None, limit: int | None = None,
              peer: tuple[Path, str] | None = None) -> dict[str, Any]:
    result_json = out / f'{name}.json'
    argv = ['localize', str(bag), '--db', str(db), '--out', str(out / f'{name}_poses'),
            '--overwrite', '--one-core', '--quiet', '--json', str(result_json)]
    limit = limit if limit is not None else args.limit
    if limit is not None:
        argv += ['--limit', str(limit)]
    for item in args.settings:
        argv += ['--set', item]
    if baseline is not None:
        argv += ['--baseline', str(baseline), '--baseline-cache',
                 str(out / f'{baseline.name}_full_features.npz')]
    if peer is not None:
        argv += ['--peer', str(peer[0]), '--peer-mode', peer[1], '--peer-cache',
                 str(out / f'{peer[0].name}_peer_map.npz')]
    env = {'OPENBLAS_NUM_THREADS': '1', 'OMP_NUM_THREADS': '1', 'MKL_NUM_THREADS': '1'}
    start = time.perf_counter()
    _call(argv, log, env)
    figures = json.loads(result_json.read_text())
    figures['name'] = name
    figures['command_seconds'] = time.perf_counter() - start
    return figures


def run(args: argparse.Namespace) -> int:
    """Run the benchmark, print and write the table; 0 when every target is met."""
    from landmark_localizer.errors import LocalizerError

    out = Path(args.out)
    if not out.parent.is_dir():
        raise LocalizerError(f'folder {out.parent} does not exist')
    from vbn_bench.localization.seeds import SEED_FAMILIES, parse_seeds

    # Typos first: a bad option leaves no output folder behind.
    cameras, conditions = _cameras(args.cameras), _conditions(args.conditions)
    seeds = parse_seeds(args.seeds)
    out.mkdir(exist_ok=True)
    log = out / 'bench.log'
    bags, cache = Path(args.bags), Path(args.cache)
    room_db = _database(Path(args.room_db) if args.room_db else out / 'room.db',
                        bags / 'room_exploration', args.build_set, log)
    effects = cache / 'room_run_effects'
    if not effects.exists():
        cache.mkdir(parents=True, exist_ok=True)  # a fresh checkout has no cache/ yet
        _call([*SEED_FAMILIES['room_run_effects'], *_EFFECTS_SEEDS, '--out', str(effects)], log)
    runs: dict[str, dict[str, Any]] = {}
    runs['room_run'] = _localize('room_run', room_db, bags / 'room_run', out, log, args)
    runs['room_run_kidnapped'] = _localize('room_run_kidnapped', room_db,
                                           bags / 'room_run_kidnapped', out, log, args)
    runs['room_run_effects'] = _localize('room_run_effects', room_db, effects, out, log, args)
    for camera in cameras:
        runs[f'room_run_{camera}'] = _lens_run(camera, cache, out, log, args)
    _seed_runs(runs, seeds, cameras, cache, out, log, args)
    for name in conditions:
        runs[f'cond_{name}'] = _condition_run(name, room_db, cache, out, log, args)
    floor_db = None
    if not args.skip_floor:
        for needed in (cache / 'floor_exploration', cache / 'floor_run'):
            if not needed.exists():
                raise LocalizerError(f'{needed} is missing: run `make cache-bags` first')
        floor_db = _database(Path(args.floor_db) if args.floor_db else out / 'floor.db',
                             cache / 'floor_exploration', args.build_set, log)
        runs['floor_run'] = _localize('floor_run', floor_db, cache / 'floor_run', out, log,
                                      args)
    if not args.skip_baseline:
        runs['baseline_room_run'] = _localize('baseline_room_run', room_db,
                                              bags / 'room_run', out, log, args,
                                              baseline=bags / 'room_exploration')
        if floor_db is not None:
            frames = min(args.baseline_frames, args.limit or args.baseline_frames)
            runs['floor_run_first'] = _localize('floor_run_first', floor_db,
                                                cache / 'floor_run', out, log, args,
                                                limit=frames)
            runs['baseline_floor_run'] = _localize(
                'baseline_floor_run', floor_db, cache / 'floor_run', out, log, args,
                baseline=cache / 'floor_exploration', limit=frames)
    if not args.skip_peer:
        _peer_runs(runs, out, log, args, bags, cache, cameras, floor_db)
    from vbn_bench.localization.report import report

    table, passed = report(runs)
    print(table)
    (out / 'results.md').write_text(table + '\n')
    (out / 'results.json').write_text(json.dumps(
        {name: {k: v for k, v in fig.items() if k != 'frames_detail'}
         for name, fig in runs.items()}, indent=1))
    return 0 if passed else 1


def _peer_runs(runs: dict[str, dict[str, Any]], out: Path, log: Path,
               args: argparse.Namespace, bags: Path, cache: Path, cameras: list[str],
               floor_db: Path | None) -> None:
    """Add the structure-based peer's runs beside ours (``peer_MODE_RUN``).

    Both variants on ``room_run``, the tracking one (what a user would run on a robot)
    on the kidnapped, effects and lens runs and on the first frames of the floor run.
    """
    from vbn_bench.localization.seeds import family_of

    room = bags / 'room_exploration'
    plan: list[tuple[str, Path, Path, str, int | None]] = [
        ('room_run', room, bags / 'room_run', 'global', None),
        ('room_run', room, bags / 'room_run', 'tracking', None),
        ('room_run_kidnapped', room, bags / 'room_run_kidnapped', 'tracking', None),
        ('room_run_effects', room, cache / 'room_run_effects', 'tracking', None)]
    for camera in cameras:
        plan.append((f'room_run_{camera}', cache / f'room_exploration_{camera}_lens',
                     cache / f'room_run_{camera}_lens', 'tracking', None))
    for name, fig in list(runs.items()):
        family, seed = family_of(name)
        if seed is not None:
            camera = family[len('room_run_'):]
            exploration = cache / f'room_exploration_{camera}_lens' if camera in cameras \
                else room
            plan.append((name, exploration, Path(fig['bag']), 'tracking', None))
    if floor_db is not None and 'floor_run_first' in runs:
        plan.append(('floor_run_first', cache / 'floor_exploration', cache / 'floor_run',
                     'tracking', runs['floor_run_first']['frames']))
    for name, exploration, bag, mode, limit in plan:
        db = Path(runs[name]['db'])
        runs[f'peer_{mode}_{name}'] = _localize(f'peer_{mode}_{name}', db, bag, out, log,
                                                args, limit=limit, peer=(exploration, mode))


def _seed_runs(runs: dict[str, dict[str, Any]], seeds: list[int], cameras: list[str],
               cache: Path, out: Path, log: Path, args: argparse.Namespace) -> None:
    """Add every room run (and lens run) at each seed, on its run's database."""
    from vbn_bench.localization.seeds import (
        SEED_FAMILIES,
        seed_bag_name,
        seed_render_argv,
        seed_run_name,
    )

    families = [*SEED_FAMILIES, *(f'room_run_{camera}' for camera in cameras)]
    for seed in seeds:
        for family in families:
            bag = _rendered(cache / seed_bag_name(family, seed),
                            seed_render_argv(family, seed), log)
            name = seed_run_name(family, seed)
            runs[name] = _localize(name, Path(runs[family]['db']), bag, out, log, args)


def _cameras(text: str) -> list[str]:
    from landmark_localizer.errors import LocalizerError
    from vbn_bench.localization.conditions import LENS_BAGS

    cameras = [c.strip() for c in text.split(',') if c.strip()]
    unknown = sorted(set(cameras) - set(LENS_BAGS))
    if unknown:
        raise LocalizerError(f'--cameras: unknown camera {unknown[0]!r} (expected '
                             f'{", ".join(LENS_BAGS)})')
    return cameras


def _rendered(bag: Path, argv: list[str] | tuple[str, ...], log: Path) -> Path:
    """Return ``bag``, rendering it with ``vbn render`` ARGV first if it is missing.

    ``vbn render`` writes its bag whole or not at all (a temporary folder renamed at
    the end), so an existing folder is a finished bag.
    """
    if not bag.exists():
        bag.parent.mkdir(parents=True, exist_ok=True)
        _call([*argv, '--out', str(bag)], log)
    return bag


def _lens_database(camera: str, cache: Path, out: Path, log: Path,
                   args: argparse.Namespace) -> Path:
    """Return the lens room's database of ``camera``, rendering and building if missing."""
    from vbn_bench.localization.conditions import lens_render_argv

    bag = _rendered(cache / f'room_exploration_{camera}_lens',
                    lens_render_argv(camera, 'exploration'), log)
    return _database(out / f'room_{camera}.db', bag, args.build_set, log)


def _lens_run(camera: str, cache: Path, out: Path, log: Path, args: argparse.Namespace
              ) -> dict[str, Any]:
    """Localize the lens room of ``camera``, rendering and building what is missing."""
    from vbn_bench.localization.conditions import lens_render_argv

    db = _lens_database(camera, cache, out, log, args)
    run = _rendered(cache / f'room_run_{camera}_lens', lens_render_argv(camera, 'run'), log)
    return _localize(f'room_run_{camera}', db, run, out, log, args)


def _conditions(text: str) -> list[str]:
    from landmark_localizer.errors import LocalizerError
    from vbn_bench.localization.conditions import CONDITIONS

    names = list(CONDITIONS) if text.strip() == 'all' else \
        [c.strip() for c in text.split(',') if c.strip()]
    unknown = sorted(set(names) - set(CONDITIONS))
    if unknown:
        raise LocalizerError(f'--conditions: unknown condition {unknown[0]!r} (expected all '
                             f'or {", ".join(CONDITIONS)})')
    if 'pitch2' in names and 'level' not in names:
        names.insert(names.index('pitch2'), 'level')  # its reference
    return names


def _condition_run(name: str, room_db: Path, cache: Path, out: Path, log: Path,
                   args: argparse.Namespace) -> dict[str, Any]:
    """Localize one condition's run, rendering and building what is missing."""
    from landmark_localizer.errors import LocalizerError
    from vbn_bench.localization.conditions import CONDITIONS, LENS_BAGS

    condition = CONDITIONS[name]
    if condition.database == 'room':
        db = room_db
    elif condition.database in LENS_BAGS:
        db = _lens_database(condition.database, cache, out, log, args)
    else:
        if not condition.exploration:
            raise LocalizerError(f'condition {name}: database {condition.database!r} has no '
                                 'exploration to render')
        bag = _rendered(cache / condition.database, condition.exploration, log)
        db = _database(out / f'{condition.database}.db', bag, args.build_set, log)
    run = _rendered(cache / condition.run_bag, condition.run, log)
    return _localize(f'cond_{name}', db, run, out, log, args)
