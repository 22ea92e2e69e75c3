"""The benchmark's room runs again at more seeds (``vbn bench-localize --seeds``).

The accuracy targets are measured over several seeds of each run, not one: one run's
p95 moves by a fifth when a setting moves which features a frame finds.
``--seeds 11,12`` renders every room run of the benchmark again with each seed, which
draws the odometry's noise, the image effects and (as ``--path-seed``) the run's path,
and localizes it against the database of the run it repeats:

- ``room_run``, ``room_run_kidnapped`` and ``room_run_effects``: the sample bags' and the
  effects run's render settings (the Makefile's ``SAMPLE_BAGS``, the benchmark's effects
  run) with the seed, on the room database;
- ``room_run_pinhole`` and ``room_run_fisheye`` (with ``--cameras``): the lens runs of
  :func:`~vbn_bench.localization.conditions.lens_render_argv` with the seed, on the
  lens room's database.

A run at seed S is named ``FAMILY@sS`` and its bag is ``--cache``/``BAG_sS``; the
structure-based peer runs on it too, so every seed has its own rows against the
targets. :func:`seeds_table` then sums each family up over its seeds: the median of
the runs' medians, the worst p95 and the worst error.
"""
from __future__ import annotations

import math
import statistics
from typing import Any

from landmark_localizer.errors import LocalizerError
from vbn_bench.localization.conditions import LENS_BAGS, lens_render_argv

__all__ = ['SEED_FAMILIES', 'family_of', 'parse_seeds', 'seed_bag_name', 'seed_render_argv',
           'seed_run_name', 'seeds_table']

_ROOM_PANORAMA = ('render', '--scene', 'room', '--camera', 'panoramic', '--speed', '0.5')
#: The room runs and their render settings (without seed and output): the Makefile's
#: ``room_run`` and ``room_run_kidnapped`` and the benchmark's effects run (``vbn
#: bench-localize`` renders that one with seed 3 on the scene's path when it is missing).
SEED_FAMILIES: dict[str, tuple[str, ...]] = {
    'room_run': (*_ROOM_PANORAMA, '--kind', 'run', '--exposure', '0.08', '--compressed',
                 '--jpeg-quality', '80'),
    'room_run_kidnapped': (*_ROOM_PANORAMA, '--kind', 'run-kidnapped', '--exposure', '0.08',
                           '--compressed', '--jpeg-quality', '80'),
    'room_run_effects': (*_ROOM_PANORAMA, '--kind', 'run', '--exposure', '0.15', '--blur',
                         '1.0', '--noise', '4', '--compressed', '--jpeg-quality', '80'),
}
#: The bag folder each family's runs are named after.
_BAGS = {'room_run': 'room_run', 'room_run_kidnapped': 'room_run_kidnapped',
         'room_run_effects': 'room_run_effects',
         **{f'room_run_{camera}': f'room_run_{camera}_lens' for camera in LENS_BAGS}}


def parse_seeds(text: str) -> list[int]:
    """Return the seeds of ``--seeds`` (comma separated positive integers, distinct).

    Example:
        >>> parse_seeds('11, 12')
        [11, 12]
    """
    seeds: list[int] = []
    for item in (part.strip() for part in text.split(',')):
        if not item:
            continue
        seed = int(item) if item.isascii() and item.isdecimal() else -1
        if seed < 1:
            # 0 is no new run: --path-seed 0 is the scene's own path, and the lens runs
            # the benchmark repeats are seed 0 already.
            raise LocalizerError(f'--seeds: {item!r} is not a positive integer')
        if seed in seeds:
            raise LocalizerError(f'--seeds: seed {item} given twice')
        seeds.append(seed)
    return seeds


def seed_run_name(family: str, seed: int) -> str:
    """Return the name of ``family``'s run at ``seed`` (``room_run@s11``)."""
    return f'{family}@s{seed}'


def family_of(name: str) -> tuple[str, int | None]:
    """Return ``(family, seed)`` of a run name (seed None for the benchmark's own run).

    Example:
        >>> family_of('room_run_effects@s12'), family_of('room_run')
        (('room_run_effects', 12), ('room_run', None))
    """
    family, _, seed = name.partition('@s')
    return family, int(seed) if seed.isdigit() else None


def seed_bag_name(family: str, seed: int) -> str:
    """Return the bag folder of ``family``'s run at ``seed`` (in ``--cache``)."""
    if family not in _BAGS:
        raise LocalizerError(f'no run family {family!r} (expected {", ".join(_BAGS)})')
    return f'{_BAGS[family]}_s{seed}'


def seed_render_argv(family: str, seed: int) -> list[str]:
    """Return ``vbn render``'s arguments (without ``--out``) of ``family``'s run at ``seed``.

    Example:
        >>> seed_render_argv('room_run', 11)[-4:]
        ['--seed', '11', '--path-seed', '11']
    """
    if family in SEED_FAMILIES:
        base = list(SEED_FAMILIES[family])
    elif family.startswith('room_run_') and family[len('room_run_'):] in LENS_BAGS:
        base = lens_render_argv(family[len('room_run_'):], 'run')
    else:
        raise LocalizerError(f'no run family {family!r} (expected {", ".join(_BAGS)})')
    return [*base, '--seed', str(seed), '--path-seed', str(seed)]


def _acc(fig: dict[str, Any]) -> dict[str, Any]:
    return fig.get('evo') or fig.get('accuracy') or {}


def _summary(figs: list[dict[str, Any]]) -> tuple[float, float, float, float, float]:
    """``(median of medians, worst p95, worst max, median heading, least availability)``.

    A run without a figure (no pose matched) makes that figure NaN: it is the worst,
    never left out.
    """
    def values(key: str) -> list[float]:
        out = [_acc(fig).get(key) for fig in figs]
        return [math.nan if v is None else float(v) for v in out]

    def median(key: str) -> float:
        v = values(key)
        return math.nan if any(math.isnan(x) for x in v) else statistics.median(v)

    def worst(key: str) -> float:
        v = values(key)
        return math.nan if any(math.isnan(x) for x in v) else max(v)

    return (median('translation_median_m'), worst('translation_p95_m'),
            worst('translation_max_m'), median('heading_median_deg'),
            min(float(fig['availability']) for fig in figs))


def seeds_table(runs: dict[str, dict[str, Any]]) -> list[str]:
    """Return each run family summed up over its seeds (Markdown lines; empty if none).

    A family is listed when it ran at more than one seed; beside ours, the peer's
    tracking variant over the same runs when it ran on all of them.
    """
    families: dict[str, list[str]] = {}
    for name in runs:
        if name.startswith('peer_'):
            continue
        family, _ = family_of(name)
        if family in _BAGS:
            families.setdefault(family, []).append(name)
    lines: list[str] = []
    for family, names in families.items():
        if len(names) < 2:
            continue
        if not lines:
            lines += ['', '| run over its seeds | runs | translation median (median of runs) | '
                      'p95 (worst run) | max (worst run) | heading median (median of runs) | '
                      'least availability |', '|' + '---|' * 7]
        seeds = ', '.join('base' if family_of(n)[1] is None else str(family_of(n)[1])
                          for n in names)
        rows = [('ours', [runs[n] for n in names])]
        peers = [runs.get(f'peer_tracking_{n}') for n in names]
        if all(peers):
            rows.append(('peer tracking', peers))
        for label, figs in rows:
            median, p95, worst, heading, available = _summary(figs)
            lines.append(f'| {family}, {label} | {seeds} | {_cm(median, 3)} | {_cm(p95, 3)} | '
                         f'{_cm(worst, 2)} | '
                         + ('-' if math.isnan(heading) else f'{heading:.4f} deg')
                         + f' | {100 * available:.1f} % |')
    return lines


def _cm(value: float, digits: int) -> str:
    return '-' if math.isnan(value) else f'{100 * value:.{digits}f} cm'
