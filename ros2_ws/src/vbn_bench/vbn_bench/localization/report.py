"""The table of ``vbn bench-localize``: every run's figures against the targets.

:func:`report` formats the ``vbn localize --json`` figures of the benchmark's runs as
one Markdown table, checks the localizer's targets (room runs: accuracy,
availability, switching, latency on one core; floor run: latency, and its TRACKING
latency against the room's) and the lens cameras' (the lens rooms and the
conditions of :mod:`vbn_bench.localization.conditions`), adds the baseline's figures
as ratios to ours, and puts the structure-based peer beside ours with the accuracy
targets (:mod:`vbn_bench.localization.peer_report`).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from vbn_bench.localization.conditions import CONDITIONS, condition_targets, lens_targets
from vbn_bench.localization.peer_report import peer_table, peer_targets
from vbn_bench.localization.seeds import family_of, seeds_table

__all__ = ['report']


def _get(fig: dict[str, Any], *path: str) -> float:
    value: Any = fig
    for key in path:
        if not isinstance(value, dict) or value.get(key) is None:
            return math.nan
        value = value[key]
    return float(value)


def _db_name(fig: dict[str, Any]) -> str:
    if fig.get('baseline'):
        return 'full features'
    if fig.get('peer'):
        return f"peer map ({fig['peer']['mode']})"
    return Path(fig['db']).name


def _accuracy(fig: dict[str, Any]) -> dict[str, Any] | None:
    return fig.get('evo') or fig.get('accuracy')


def report(runs: dict[str, dict[str, Any]]) -> tuple[str, bool]:
    """Format the runs as the table and check the targets.

    Args:
        runs: ``vbn localize --json`` figures by run name.

    Returns:
        The table (Markdown) and whether every target is met.
    """
    from vbn_bench.localization.evaluation import Thresholds

    t = Thresholds()
    lines = ['| run | db | frames | poses | availability | predicted changes | '
             'trans. median (evo) | trans. p95 (evo) | heading median | recovery (frames) | '
             'latency p50 | TRACKING p95 | LOST p95 | CPU TRACKING p95 | CPU LOST p95 | '
             'db size |',
             '|' + '---|' * 16]
    for name, fig in runs.items():
        acc = _accuracy(fig) or {}
        changes = fig.get('changes', {})
        frac = changes.get('predicted_fraction')
        rec = fig.get('recovery') or []
        lines.append(
            f"| {name} | {_db_name(fig)}"
            f" | {fig['frames']} | {fig['poses']} | {fig['availability'] * 100:.1f} % | "
            + (f"{frac * 100:.0f} % ({changes['predicted']}/"
               f"{changes['predicted'] + changes['after_loss']})"
               if frac is not None and not (fig.get('baseline') or fig.get('peer'))
               else '-') + ' | '
            + (f"{acc['translation_median_m'] * 100:.2f} cm | "
               f"{acc['translation_p95_m'] * 100:.2f} cm | {acc['heading_median_deg']:.3f} deg"
               if acc else '- | - | -') + ' | '
            + (', '.join('never' if r is None else str(r) for r in rec) or '-') + ' | '
            + f"{_get(fig, 'latency', 'p50') * 1e3:.1f} ms | "
            f"{_get(fig, 'latency', 'tracking_p95') * 1e3:.1f} ms | "
            f"{_get(fig, 'latency', 'lost_p95') * 1e3:.1f} ms | "
            f"{_get(fig, 'cpu_latency', 'tracking_p95') * 1e3:.1f} ms | "
            f"{_get(fig, 'cpu_latency', 'lost_p95') * 1e3:.1f} ms | "
            f"{fig['size_bytes'] / 1e6:.2f} MB |")
    checks: list[tuple[str, float, float, bool]] = []

    def target(label: str, value: float, limit: float, at_most: bool = True) -> None:
        checks.append((label, value, limit, at_most))

    for name, fig in runs.items():   # each run, and each of its seeds (``--seeds``)
        checks += _run_checks(family_of(name)[0], name, fig)
    room = runs.get('room_run')
    for name in CONDITIONS:
        if f'cond_{name}' in runs:
            checks += condition_targets(name, runs[f'cond_{name}'], runs)
    floor = runs.get('floor_run')
    if floor:
        target('floor_run latency TRACKING p95, s', _get(floor, 'latency', 'tracking_p95'),
               t.tracking_p95_s)
        target('floor_run latency LOST p95, s', _get(floor, 'latency', 'lost_p95'),
               t.lost_p95_s)
        target('floor_run CPU time TRACKING p95, s',
               _get(floor, 'cpu_latency', 'tracking_p95'), t.tracking_p95_s)
    checks += peer_targets(runs)
    lines += ['', '| target | measured | limit | |', '|---|---|---|---|']
    passed = True
    for label, value, limit, at_most in checks:
        ok = math.isfinite(value) and (value <= limit if at_most else value >= limit)
        passed &= ok
        lines.append(f"| {label} | {value:.4g} | {'<=' if at_most else '>='} {limit:g} | "
                     f"{'PASS' if ok else 'FAIL'} |")
    if room and floor:
        ratio = _get(floor, 'latency', 'tracking_p95') / _get(room, 'latency', 'tracking_p95')
        lines.append(f'| TRACKING p95 latency floor / room (must not grow) | {ratio:.2f} | '
                     f'- | {room["size_bytes"] / 1e6:.2f} MB vs {floor["size_bytes"] / 1e6:.2f}'
                     ' MB databases |')
    if floor:
        lines += _floor_report(floor)
    lines += _ratios(runs)
    lines += peer_table(runs)
    lines += seeds_table(runs)
    lines.append('')
    lines.append('RESULT: ' + ('PASS (every target met)' if passed else 'FAIL (see FAIL rows)'))
    return '\n'.join(lines), passed


def _run_checks(family: str, name: str, fig: dict[str, Any]
                ) -> list[tuple[str, float, float, bool]]:
    """Return the targets of run ``name`` of ``family`` (a seed run: its family's)."""
    from vbn_bench.localization.evaluation import Thresholds

    t = Thresholds()
    acc = _accuracy(fig) or {}
    checks: list[tuple[str, float, float, bool]] = []

    def target(label: str, value: float, limit: float, at_most: bool = True) -> None:
        checks.append((f'{name} {label}', value, limit, at_most))

    if family in ('room_run', 'room_run_effects'):
        target('translation median (evo), m', acc.get('translation_median_m', math.nan),
               t.translation_median_m)
        target('translation p95 (evo), m', acc.get('translation_p95_m', math.nan),
               t.translation_p95_m)
        target('heading median, deg', acc.get('heading_median_deg', math.nan),
               t.heading_median_deg)
        target('availability', fig['availability'], t.availability, False)
        target('region changes by prediction', _get(fig, 'changes', 'predicted_fraction'),
               t.predicted_fraction, False)
    if family == 'room_run':
        target('latency TRACKING p95, s', _get(fig, 'latency', 'tracking_p95'),
               t.tracking_p95_s)
        target('latency LOST p95, s', _get(fig, 'latency', 'lost_p95'), t.lost_p95_s)
        target('CPU time TRACKING p95, s', _get(fig, 'cpu_latency', 'tracking_p95'),
               t.tracking_p95_s)
    if family == 'room_run_kidnapped':
        rec = fig.get('recovery') or [None]
        worst = math.nan if any(r is None for r in rec) else max(rec)
        target('frames to a correct pose', worst, t.recovery_frames)
        target('latency LOST p95, s', _get(fig, 'latency', 'lost_p95'), t.lost_p95_s)
        target('CPU time LOST p95, s', _get(fig, 'cpu_latency', 'lost_p95'), t.lost_p95_s)
    for camera in ('pinhole', 'fisheye'):
        if family == f'room_run_{camera}':
            checks += lens_targets(name, fig, latency=camera == 'pinhole')
    return checks


def _floor_report(floor: dict[str, Any]) -> list[str]:
    """floor_run's accuracy and availability (reported: the targets are the room's).

    Split by whether the true position lies in one of the database's regions: the
    builder's decomposition (sigma rule) leaves some k-coverable poses in none.
    """
    acc = _accuracy(floor) or {}
    lines = ['', '| floor_run (reported) | frames | availability | translation median | '
             'translation p95 | region changes by prediction |', '|---|---|---|---|---|---|',
             f"| all | {floor['frames']} | {100 * floor['availability']:.1f} % | "
             f"{100 * acc.get('translation_median_m', math.nan):.2f} cm | "
             f"{100 * acc.get('translation_p95_m', math.nan):.2f} cm | "
             f"{100 * _get(floor, 'changes', 'predicted_fraction'):.0f} % |"]
    for name, part in (floor.get('coverage') or {}).items():
        lines.append(f"| {name} the database's regions | {part['frames']} | "
                     f"{100 * (part['availability'] or math.nan):.1f} % | "
                     f"{100 * (part['translation_median_m'] or math.nan):.2f} cm | "
                     f"{100 * (part['translation_p95_m'] or math.nan):.2f} cm | - |")
    return lines


def _ratios(runs: dict[str, dict[str, Any]]) -> list[str]:
    pairs = [('room_run', 'baseline_room_run'), ('floor_run_first', 'baseline_floor_run')]
    lines: list[str] = []
    for ours_name, base_name in pairs:
        ours, base = runs.get(ours_name), runs.get(base_name)
        if not ours or not base:
            continue
        if not lines:
            lines += ['', '| baseline / ours | translation median | translation p95 | '
                      'heading median | availability | latency p50 | latency p95 | '
                      'database size |', '|' + '---|' * 8]
        a, b = _accuracy(ours) or {}, _accuracy(base) or {}

        def ratio(x: float, y: float) -> str:
            return f'{y / x:.2f}' if x and math.isfinite(x) and math.isfinite(y) else '-'

        lines.append(
            f'| {ours_name} ({ours["frames"]} frames) | '
            f"{ratio(a.get('translation_median_m', math.nan), b.get('translation_median_m', math.nan))} | "  # noqa: E501
            f"{ratio(a.get('translation_p95_m', math.nan), b.get('translation_p95_m', math.nan))} | "  # noqa: E501
            f"{ratio(a.get('heading_median_deg', math.nan), b.get('heading_median_deg', math.nan))} | "  # noqa: E501
            f"{ratio(ours['availability'], base['availability'])} | "
            f"{ratio(_get(ours, 'latency', 'p50'), _get(base, 'latency', 'p50'))} | "
            f"{ratio(_get(ours, 'latency', 'p95'), _get(base, 'latency', 'p95'))} | "
            f"{ratio(ours['size_bytes'], base['size_bytes'])} |")
    return lines
