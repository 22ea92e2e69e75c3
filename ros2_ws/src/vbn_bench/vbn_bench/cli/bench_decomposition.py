"""``vbn bench-decomposition``: reproduce the thesis's Tables 8.2-8.4 and Figure 8.3."""
from __future__ import annotations

import argparse
from collections.abc import Iterator
from contextlib import contextmanager
import logging
from pathlib import Path
from typing import Any

from landmark_db.defaults import THESIS

__all__ = ['register', 'run']

_LOG = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bench-decomposition`` subcommand."""
    parser = subparsers.add_parser(
        'bench-decomposition',
        help='benchmark the decomposition algorithms on random worlds (Tables 8.2-8.4)',
        description='Generate random worlds of the four settings of thesis Section 8.2, '
                    f'decompose each with A1, A2, A3, B1, B2, C and best (k={THESIS.k}, '
                    f'rho={THESIS.rho}, sigma={THESIS.sigma}, alpha={THESIS.alpha}), '
                    'validate every decomposition, and print our '
                    "Tables 8.2-8.4 beside the thesis's, the time per algorithm, the "
                    'improvement of best over B2 and, on reduced-size worlds, every '
                    "heuristic's approximation ratio against the exact optimum. Writes "
                    'results.json, results.csv, tables.txt and PNG figures into --out. '
                    'Exits 1 if any decomposition fails validation.',
    )
    parser.add_argument('--worlds', type=int, default=300,
                        help='worlds per setting (default: 300, as in the thesis)')
    parser.add_argument('--settings', default='1,2,3,4',
                        help='comma-separated setting numbers (default: 1,2,3,4)')
    parser.add_argument('--out', default='bench-decomposition', metavar='DIR',
                        help='output directory (default: ./bench-decomposition)')
    parser.add_argument('--seed', type=int, default=0,
                        help='base seed: world i of setting s is `vbn simulate --setting s '
                             '--seed SEED+i` (default: 0)')
    parser.add_argument('--processes', type=int, default=2,
                        help='worker processes (default: 2); results do not depend on it')
    parser.add_argument('--small-worlds', type=int, default=10,
                        help='reduced-size worlds per setting for the approximation ratios '
                             'against the exact optimum (default: 10; 0 skips)')
    parser.add_argument('--reduced', action='store_true',
                        help='run the main tables on reduced-size worlds too (quick check)')
    parser.add_argument('--algorithms', default='A1,A2,A3,B1,B2,C,best',
                        help='comma-separated algorithms (default: A1,A2,A3,B1,B2,C,best)')
    parser.add_argument('--calibrate', action='store_true',
                        help='only measure the features visible per pose against Table 8.4 '
                             'and suggest feature densities')
    parser.add_argument('--scaling', action='store_true',
                        help='only run the scaling benchmark (worlds up to 100,000 poses '
                             'and 10,000 features, timing B2)')
    parser.add_argument('--scaling-algorithms', default='B2',
                        help='algorithms timed by --scaling (default: B2)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and write its outputs."""
    import json
    import sys

    from landmark_db.errors import LandmarkDbError
    from vbn_common.atomic import check_output_folder, write_text_atomic

    settings = _int_list(args.settings, '--settings')
    if any(s not in (1, 2, 3, 4) for s in settings):
        raise LandmarkDbError(f'--settings must list numbers from 1 to 4, got {args.settings!r}')
    if args.worlds < 1:
        raise LandmarkDbError(f'--worlds must be >= 1, got {args.worlds}')
    if args.small_worlds < 0:
        raise LandmarkDbError(f'--small-worlds must be >= 0, got {args.small_worlds}')
    if args.processes < 1:
        raise LandmarkDbError(f'--processes must be >= 1, got {args.processes}')
    if args.seed < 0:
        raise LandmarkDbError(f'--seed must be >= 0, got {args.seed}')
    from landmark_db.decomposition import ALGORITHMS

    algorithms = tuple(a.strip() for a in args.algorithms.split(',') if a.strip())
    unknown = [a for a in algorithms if a not in ALGORITHMS]
    if unknown or not algorithms:
        raise LandmarkDbError(f'unknown algorithm(s) {unknown}; choose from '
                              f'{", ".join(ALGORITHMS)}')
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise LandmarkDbError(f'output folder {out} is a file')
    if not out.exists():
        # Create --out itself but not a missing parent: a mistyped path is an error.
        check_output_folder(out)
        out.mkdir()

    if args.calibrate:
        from vbn_bench.decomposition.calibration import calibrate, format_calibration

        rows = calibrate(settings, worlds=args.worlds, seed=args.seed,
                         processes=args.processes)
        text = format_calibration(rows)
        print(text)
        write_text_atomic(out / 'calibration.txt', text + '\n')
        write_text_atomic(out / 'calibration.json', json.dumps(rows, indent=1))
        return 0

    if args.scaling:
        from vbn_bench.decomposition.scaling import format_scaling, run_scaling

        scaling_algorithms = tuple(a.strip() for a in args.scaling_algorithms.split(',')
                                   if a.strip())
        bad = [a for a in scaling_algorithms if a not in ALGORITHMS]
        if bad:
            raise LandmarkDbError(f'unknown algorithm(s) {bad} in --scaling-algorithms')
        from tqdm import tqdm

        from vbn_bench.decomposition.scaling import DEFAULT_SIZES

        with tqdm(total=len(DEFAULT_SIZES) * len(scaling_algorithms), desc='scaling runs',
                  unit='run', file=sys.stderr) as bar:
            def progress(row: dict[str, object]) -> None:
                bar.write(f"  {row['poses']} poses, {row['features']} features: "
                          f"{row['algorithm']} {row['seconds']:.2f} s", file=sys.stderr)
                bar.update()

            rows = run_scaling(DEFAULT_SIZES, algorithms=scaling_algorithms, seed=args.seed,
                               progress=progress)
        text = format_scaling(rows)
        print(text)
        write_text_atomic(out / 'scaling.txt', text + '\n')
        write_text_atomic(out / 'scaling.json', json.dumps(rows, indent=1))
        return 0 if all(r['valid'] for r in rows) else 1

    from vbn_bench.decomposition.figures import (
        plot_bar_chart,
        plot_k_rho_sweep,
        plot_world_decompositions,
    )
    from vbn_bench.decomposition.reference import (
        THESIS_TABLE_8_2,
        THESIS_TABLE_8_3,
        THESIS_TABLE_8_4,
    )
    from vbn_bench.decomposition.report import (
        approximation_ratios,
        format_report,
        improvement_over_b2,
        summarize,
    )
    from vbn_bench.decomposition.runner import (
        FULL,
        REDUCED,
        WORLD_CLASS_LABELS,
        BenchConfig,
        planned_worlds,
        records_as_dicts,
        run_benchmark,
    )
    from visibility_builder.plotting import save_decomposition_figure

    config = BenchConfig(settings=settings, worlds=args.worlds, seed=args.seed,
                         algorithms=algorithms, reduced=args.reduced,
                         small_worlds=args.small_worlds, processes=args.processes)

    with _world_bars(planned_worlds(config), WORLD_CLASS_LABELS) as bars:
        records, figure_worlds = run_benchmark(
            config, progress=lambda world_class, done, total: bars[world_class].update())
    summary = summarize(records)
    main_class = REDUCED if config.reduced else FULL
    text = format_report(summary, records, list(algorithms), main_class=main_class)
    print(text)
    write_text_atomic(out / 'tables.txt', text + '\n')
    results = {
        'config': {'settings': list(settings), 'worlds': config.worlds, 'seed': config.seed,
                   'algorithms': list(algorithms), 'k': config.k, 'rho': config.rho,
                   'sigma': config.sigma, 'alpha': config.alpha, 'spacing': config.spacing,
                   'reduced': config.reduced, 'small_worlds': config.small_worlds,
                   'small_sigma': config.small_sigma},
        'summary': summary,
        'improvement_over_b2_percent': improvement_over_b2(summary, world_class=main_class),
        'approximation_ratios': approximation_ratios(records),
        'thesis_reference': {'table_8_2': THESIS_TABLE_8_2, 'table_8_3': THESIS_TABLE_8_3,
                             'table_8_4': THESIS_TABLE_8_4},
        'records': records_as_dicts(records),
    }
    write_text_atomic(out / 'results.json', json.dumps(results, indent=1))
    _write_csv(out / 'results.csv', results['records'])
    plot_bar_chart(summary, list(algorithms), out / 'fig_8_3_bars.png', world_class=main_class)
    for setting, outcome in sorted(figure_worlds.items()):
        plot_world_decompositions(outcome, list(algorithms),
                                  out / f'decomposition_setting{setting}.png', config.k)
        simulated = outcome.simulated
        for algorithm in ('B2', 'best'):
            d = (outcome.decompositions or {}).get(algorithm)
            if d is not None:
                save_decomposition_figure(
                    out / f'decomposition_setting{setting}_{algorithm}.png', simulated.world,
                    d.regions, config.k, d.uncovered, scene=simulated.scene,
                    title=f'{simulated.world.name}, {algorithm}: {len(d.regions)} regions, '
                          f'{len(d.uncovered)} uncovered k-coverable poses (x)')
    from vbn_worlds.simulator.settings import get_setting, small_setting
    from vbn_worlds.simulator.simulate import simulate_world

    # Type 2 features (setting 2) leave enough common features for k up to 10 on a
    # small world; Type 1 worlds become mostly uncovered at k >= 6 with rho = 1.
    sweep_setting = 2 if 2 in settings else settings[0]
    sweep_world = simulate_world(small_setting(get_setting(sweep_setting)), config.seed)
    _, sweep = plot_k_rho_sweep(sweep_world, out / 'decomposition_k_rho_sweep.png',
                                seed=config.seed)
    sweep_problems = [row for row in sweep if row['problems']]
    for row in sweep_problems:
        print(f"!!! k/rho sweep k={row['k']} rho={row['rho']} INVALID: "
              f"{'; '.join(row['problems'][:2])}", file=sys.stderr)
    print(f'wrote {out}/results.json, results.csv, tables.txt and figures', file=sys.stderr)
    return 0 if all(r.valid for r in records) and not sweep_problems else 1


@contextmanager
def _world_bars(planned: dict[str, int], labels: dict[str, str]) -> Iterator[dict[str, Any]]:
    """One tqdm bar per world class: the main tables' worlds, then the small worlds."""
    import sys

    from tqdm import tqdm

    bars = {world_class: tqdm(total=total, desc=labels.get(world_class, world_class),
                              unit='world', position=index, file=sys.stderr)
            for index, (world_class, total) in enumerate(planned.items())}
    try:
        yield bars
    finally:
        for bar in bars.values():
            bar.close()


def _int_list(text: str, name: str) -> tuple[int, ...]:
    from landmark_db.errors import LandmarkDbError

    try:
        values = tuple(int(part) for part in text.split(',') if part.strip())
    except ValueError as error:
        raise LandmarkDbError(f'{name} must be comma-separated integers, got {text!r}') from error
    if not values:
        raise LandmarkDbError(f'{name} is empty')
    return values


def _write_csv(path: Path, rows: list[dict[str, object]]) -> None:
    import csv

    from vbn_common.atomic import atomic_output

    if not rows:
        return
    fields = [k for k in rows[0] if k != 'problems'] + ['problems']
    with atomic_output(path) as temporary, open(temporary, 'w', newline='') as handle:
        writer = csv.DictWriter(handle, fieldnames=fields)
        writer.writeheader()
        for row in rows:
            writer.writerow({**row, 'problems': ' | '.join(row.get('problems', []))})
