"""Summaries and text tables of the decomposition benchmark, beside the thesis's numbers."""
from __future__ import annotations

from collections import defaultdict
from typing import Any

import numpy as np

from vbn_bench.decomposition.reference import (
    THESIS_TABLE_8_2,
    THESIS_TABLE_8_3,
    THESIS_TABLE_8_4,
)
from vbn_bench.decomposition.runner import FULL, REDUCED, SMALL, RunRecord

__all__ = ['approximation_ratios', 'format_report', 'improvement_over_b2', 'summarize']


def summarize(records: list[RunRecord]) -> dict[str, Any]:
    """Average the records per world class, setting and algorithm.

    Returns:
        ``{'cells': [...], 'worlds': [...]}``: one cell per (class, setting, algorithm)
        with means of regions, poses per region, used features, uncovered poses and
        seconds, the count of runs and of invalid or failed runs; one entry per
        (class, setting) with the worlds' mean size and visibility statistics.
    """
    groups: dict[tuple[str, int, str], list[RunRecord]] = defaultdict(list)
    for record in records:
        groups[(record.world_class, record.setting, record.algorithm)].append(record)
    cells = []
    for (world_class, setting, algorithm), group in sorted(groups.items()):
        ok = [r for r in group if r.valid]
        cells.append({
            'world_class': world_class, 'setting': setting, 'algorithm': algorithm,
            'runs': len(group), 'invalid': len(group) - len(ok),
            'regions': _mean([r.regions for r in ok]),
            'regions_std': _std([r.regions for r in ok]),
            'poses_per_region': _mean([r.mean_region_poses for r in ok]),
            'used_features': _mean([r.used_features for r in ok]),
            'uncovered': _mean([r.uncovered for r in ok]),
            'seconds': _mean([r.seconds for r in group if not _crashed(r)]),
            'seconds_max': max((r.seconds for r in group if not _crashed(r)), default=0.0),
            'cpu_seconds': _mean([r.cpu_seconds for r in group if not _crashed(r)]),
            'cpu_seconds_max': max((r.cpu_seconds for r in group if not _crashed(r)),
                                   default=0.0),
        })
    worlds: dict[tuple[str, int], dict[int, RunRecord]] = defaultdict(dict)
    for record in records:
        worlds[(record.world_class, record.setting)].setdefault(record.world_seed, record)
    world_stats = []
    for (world_class, setting), by_seed in sorted(worlds.items()):
        rs = list(by_seed.values())
        world_stats.append({
            'world_class': world_class, 'setting': setting, 'worlds': len(rs),
            'poses': _mean([r.n_poses for r in rs]),
            'features': _mean([r.n_features for r in rs]),
            'coverable': _mean([r.n_coverable for r in rs]),
            'mean_visible': _mean([r.mean_visible for r in rs]),
            'mean_visible_std': _std([r.mean_visible for r in rs]),
        })
    return {'cells': cells, 'worlds': world_stats}


def improvement_over_b2(summary: dict[str, Any], algorithm: str = 'best',
                        world_class: str = FULL) -> dict[str, float]:
    """Percent fewer regions of ``algorithm`` than B2, per setting and averaged.

    Returns:
        ``{'1': pct, ..., 'mean': pct}`` (settings where both ran): positive when
        ``algorithm`` needs fewer regions than B2, negative when it needs more.
    """
    cell = _cell_index(summary)
    out: dict[str, float] = {}
    for (cls, setting, alg), c in cell.items():
        if cls != world_class or alg != 'B2':
            continue
        other = cell.get((cls, setting, algorithm))
        if other and c['regions'] > 0 and not np.isnan(other['regions']):
            out[str(setting)] = 100.0 * (c['regions'] - other['regions']) / c['regions']
    if out:
        out['mean'] = float(np.mean(list(out.values())))
    return out


def approximation_ratios(records: list[RunRecord]) -> dict[str, dict[str, float]]:
    """Each algorithm's regions divided by the exact optimum's, on the small worlds.

    Only worlds where the exact solver returned a valid decomposition with at least
    one region count; invalid heuristic runs are excluded and counted.

    Returns:
        ``{algorithm: {'mean', 'max', 'worlds', 'optimal_share'}}`` plus, under
        ``'exact'``, the mean optimum.
    """
    exact: dict[tuple[int, int], int] = {}
    for r in records:
        if r.world_class == SMALL and r.algorithm == 'exact' and r.valid and r.regions > 0:
            exact[(r.setting, r.world_seed)] = r.regions
    ratios: dict[str, list[float]] = defaultdict(list)
    for r in records:
        if r.world_class != SMALL or r.algorithm == 'exact' or not r.valid:
            continue
        optimum = exact.get((r.setting, r.world_seed))
        if optimum:
            ratios[r.algorithm].append(r.regions / optimum)
    out = {alg: {'mean': float(np.mean(v)), 'max': float(np.max(v)), 'worlds': len(v),
                 'optimal_share': float(np.mean(np.isclose(v, 1.0)))}
           for alg, v in ratios.items()}
    if exact:
        out['exact'] = {'mean_regions': float(np.mean(list(exact.values()))),
                        'worlds': len(exact)}
    return out


def format_report(summary: dict[str, Any], records: list[RunRecord], algorithms: list[str],
                  main_class: str = FULL) -> str:
    """Format the tables, timings, improvement and ratios as plain text."""
    cell = _cell_index(summary)
    settings = sorted({c['setting'] for c in summary['cells'] if c['world_class'] == main_class})
    lines: list[str] = []
    worlds = {(w['world_class'], w['setting']): w for w in summary['worlds']}
    label = 'reduced-size worlds' if main_class == REDUCED else 'full-size worlds'
    counts = ', '.join(f"setting {s}: {worlds[(main_class, s)]['worlds']}" for s in settings
                       if (main_class, s) in worlds)
    lines.append(f'Decomposition benchmark on {label} ({counts}).')
    lines.append('Each cell: ours [thesis]. Thesis numbers are REFERENCE DATA copied from '
                 'Tables 8.2-8.4 (300 worlds per setting).')
    lines.append('')
    for title, key, table in (
            ('Table 8.2: average number of regions in a decomposition', 'regions',
             THESIS_TABLE_8_2),
            ('Table 8.3: average number of poses per region', 'poses_per_region',
             THESIS_TABLE_8_3),
            ('Figure 8.3 (right): average number of used features', 'used_features', None),
            ('Average number of uncovered k-coverable poses', 'uncovered', None),
            ('Mean wall-clock time per world (s, one process)', 'seconds', None),
            ('Mean CPU time per world (s)', 'cpu_seconds', None),
            ('Largest CPU time on one world (s)', 'cpu_seconds_max', None)):
        lines.append(title)
        lines.append(_row(['Setting', *algorithms], first=8))
        for s in settings:
            row = [str(s)]
            for alg in algorithms:
                c = cell.get((main_class, s, alg))
                ours = '-' if c is None or np.isnan(c[key]) else _fmt(c[key], key)
                ref = table.get(s, {}).get(alg) if table else None
                row.append(f'{ours} [{ref:.2f}]' if ref is not None else ours)
            lines.append(_row(row, first=8))
        lines.append('')
    lines.append('Table 8.4: average number of features visible from a pose')
    lines.append(_row(['Setting', 'ours', 'thesis', 'poses', 'features', 'k-coverable'],
                      first=8, width=12))
    for s in settings:
        w = worlds.get((main_class, s))
        if w is None:
            continue
        lines.append(_row([str(s), f"{w['mean_visible']:.1f}", f'{THESIS_TABLE_8_4[s]}',
                           f"{w['poses']:.0f}", f"{w['features']:.0f}",
                           f"{w['coverable']:.0f}"], first=8, width=12))
    lines.append('')
    improvement = improvement_over_b2(summary, world_class=main_class)
    if improvement:
        per = ', '.join(f'setting {k}: {_fewer_or_more(v)}' for k, v in improvement.items()
                        if k != 'mean')
        lines.append(f"Regions of the new heuristic 'best' against B2: {per}; "
                     f"mean over settings {_fewer_or_more(improvement['mean'])}")
        lines.append('')
    ratios = approximation_ratios(records)
    if ratios:
        small = [w for w in summary['worlds'] if w['world_class'] == SMALL]
        sizes = ', '.join(f"setting {w['setting']}: {w['worlds']} worlds, {w['poses']:.0f} "
                          f"poses, {w['features']:.0f} features, {w['mean_visible']:.1f} "
                          'visible/pose' for w in small)
        sigma = next((r.sigma for r in records if r.world_class == SMALL), 0)
        lines.append(f'Approximation ratio (regions / exact optimum) on reduced-size worlds '
                     f'(sigma={sigma}; {sizes})')
        exact = ratios.get('exact')
        if exact:
            lines.append(f"  exact optimum: mean {exact['mean_regions']:.2f} regions over "
                         f"{exact['worlds']} worlds")
        for alg in [a for a in algorithms if a in ratios]:
            r = ratios[alg]
            lines.append(f"  {alg:>5}: mean {r['mean']:.3f}  max {r['max']:.3f}  "
                         f"optimal in {100 * r['optimal_share']:.0f}% of {r['worlds']} worlds")
        lines.append('')
    failures = [r for r in records if not r.valid]
    if failures:
        lines.append(f'!!! {len(failures)} RUNS FAILED VALIDATION OR RAISED !!!')
        for r in failures[:20]:
            lines.append(f'  {r.world_class} setting {r.setting} seed {r.world_seed} '
                         f'{r.algorithm}: {"; ".join(r.problems[:2])}')
    else:
        lines.append(f'All {len(records)} decompositions passed the validator.')
    return '\n'.join(lines)


def _fewer_or_more(percent: float) -> str:
    """Say ``'8.1 % fewer'`` or ``'2.0 % more'`` rather than a sign that reads backwards."""
    if percent > 0:
        return f'{percent:.1f} % fewer'
    if percent < 0:
        return f'{-percent:.1f} % more'
    return 'as many'


def _crashed(record: RunRecord) -> bool:
    return bool(record.problems) and record.regions == 0 and record.seconds == 0.0


def _cell_index(summary: dict[str, Any]) -> dict[tuple[str, int, str], dict[str, Any]]:
    return {(c['world_class'], c['setting'], c['algorithm']): c for c in summary['cells']}


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else float('nan')


def _std(values: list[float]) -> float:
    return float(np.std(values)) if values else float('nan')


def _fmt(value: float, key: str) -> str:
    return f'{value:.3f}' if 'seconds' in key else f'{value:.2f}'


def _row(cells: list[str], first: int = 8, width: int = 17) -> str:
    return cells[0].ljust(first) + ''.join(c.rjust(width) for c in cells[1:])
