"""Ours beside the structure-based peer in ``vbn bench-localize``.

The peer (:mod:`.peer`) runs on the same bags, on the same pinned core, in the same
benchmark; its runs are named ``peer_global_RUN`` and ``peer_tracking_RUN`` after ours.
:func:`peer_table` prints them side by side with the ratios peer / ours, and
:func:`peer_targets` checks the accuracy targets on every run that has a peer:
translation median and p95, heading median, TRACKING latency (absolute and as a share of
the peer's), and the database against the peer's compact map.
"""
from __future__ import annotations

import math
from typing import Any

from vbn_bench.localization.peer import PEER_MODES

__all__ = ['PeerTargets', 'peer_table', 'peer_targets']


class PeerTargets:
    """The accuracy limits."""

    translation_median_m = 0.001
    translation_p95_m = 0.003
    heading_median_deg = 0.02
    tracking_p95_s = 0.012
    latency_share = 0.1      # of the peer's TRACKING p95 (its fastest variant)
    size_share = 1.0 / 3.0   # of the peer's compact map
    largest_error_m = 0.5


def _acc(fig: dict[str, Any]) -> dict[str, Any]:
    return fig.get('evo') or fig.get('accuracy') or {}


def _num(fig: dict[str, Any], *path: str) -> float:
    value: Any = fig
    for key in path:
        if not isinstance(value, dict) or value.get(key) is None:
            return math.nan
        value = value[key]
    return float(value)


def _peers(runs: dict[str, dict[str, Any]], name: str) -> list[tuple[str, dict[str, Any]]]:
    return [(mode, runs[f'peer_{mode}_{name}']) for mode in PEER_MODES
            if f'peer_{mode}_{name}' in runs]


def _row(label: str, fig: dict[str, Any], size: str) -> str:
    a = _acc(fig)
    return (f"| {label} | {100 * fig['availability']:.1f} % | "
            f"{100 * a.get('translation_median_m', math.nan):.3f} / "
            f"{100 * a.get('translation_p95_m', math.nan):.3f} / "
            f"{100 * a.get('translation_max_m', math.nan):.2f} cm | "
            f"{a.get('heading_median_deg', math.nan):.4f} deg | "
            f"{1e3 * _num(fig, 'latency', 'p50'):.1f} / "
            f"{1e3 * _num(fig, 'latency', 'tracking_p95'):.1f} ms | {size} |")


def peer_table(runs: dict[str, dict[str, Any]]) -> list[str]:
    """Return the side-by-side table (Markdown lines), empty without peer runs."""
    lines: list[str] = []
    for name, ours in runs.items():
        peers = _peers(runs, name)
        if name.startswith('peer_') or not peers:
            continue
        if not lines:
            lines += ['', '| run, localizer | frames posed | translation median / p95 / max | '
                      'heading median | latency p50 / TRACKING p95 | map on disk |',
                      '|' + '---|' * 6]
        lines.append(_row(f'{name} ({ours["frames"]} frames), ours', ours,
                          f"{ours['size_bytes'] / 1e6:.2f} MB"))
        a = _acc(ours)
        for mode, fig in peers:
            peer = fig.get('peer') or {}
            size = (f"{_num(peer, 'map_bytes') / 1e6:.2f} MB "
                    f"({_num(peer, 'compact_bytes') / 1e6:.2f} MB compact)")
            lines.append(_row(f'{name}, peer {mode}', fig, size))
            b = _acc(fig)

            def ratio(x: float, y: float) -> str:
                return f'{x / y:.2f}' if y and math.isfinite(x) and math.isfinite(y) else '-'

            lines.append(
                f'| ours / peer {mode} | - | '
                f"{ratio(a.get('translation_median_m', math.nan), b.get('translation_median_m', math.nan))} / "  # noqa: E501
                f"{ratio(a.get('translation_p95_m', math.nan), b.get('translation_p95_m', math.nan))} | "  # noqa: E501
                f"{ratio(a.get('heading_median_deg', math.nan), b.get('heading_median_deg', math.nan))} | "  # noqa: E501
                f"{ratio(_num(ours, 'latency', 'p50'), _num(fig, 'latency', 'p50'))} / "
                f"{ratio(_num(ours, 'latency', 'tracking_p95'), _num(fig, 'latency', 'tracking_p95'))} | "  # noqa: E501
                f"{ratio(ours['size_bytes'], _num(peer, 'compact_bytes'))} of compact |")
    return lines


def peer_targets(runs: dict[str, dict[str, Any]]) -> list[tuple[str, float, float, bool]]:
    """Return ``(label, measured, limit, at_most)`` for every run that has a peer run."""
    t = PeerTargets()
    checks: list[tuple[str, float, float, bool]] = []
    for name, ours in runs.items():
        peers = _peers(runs, name)
        if name.startswith('peer_') or not peers:
            continue
        a = _acc(ours)
        checks += [
            (f'{name} translation median (evo), m',
             a.get('translation_median_m', math.nan), t.translation_median_m, True),
            (f'{name} translation p95 (evo), m',
             a.get('translation_p95_m', math.nan), t.translation_p95_m, True),
            (f'{name} heading median, deg', a.get('heading_median_deg', math.nan),
             t.heading_median_deg, True),
            (f'{name} largest translation error, m',
             a.get('translation_max_m', math.nan), t.largest_error_m, True),
            (f'{name} latency TRACKING p95, s',
             _num(ours, 'latency', 'tracking_p95'), t.tracking_p95_s, True)]
        fastest = min(_num(fig, 'latency', 'tracking_p95') for _, fig in peers)
        checks.append((f"{name} TRACKING p95 / the peer's", _num(ours, 'latency',
                       'tracking_p95') / fastest, t.latency_share, True))
        compact = min(_num(fig.get('peer') or {}, 'compact_bytes') for _, fig in peers)
        checks.append((f"{name} database / the peer's compact map",
                       ours['size_bytes'] / compact, t.size_share, True))
    return checks
