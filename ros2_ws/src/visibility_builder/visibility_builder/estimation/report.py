"""The figures of ``vbn estimate-poses --report DIR``.

- ``view_graph.png``: the places at their estimated positions, the pairs of views that
  measured a direction between two places (kept by the fits: grey; dropped: red) and the
  odometry's steps between consecutive places (dotted): where the graph is thin or in
  pieces, the estimate rests on the odometry.
- ``trajectories.png``: the images' positions by the odometry and by the estimate (and
  the ground truth, SE(2)-aligned, when the bag has it), all in ``map``.
- ``summary.json``: the figures the command prints.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ['write_estimation_report']


def write_estimation_report(folder: Path, result: Any, figures: dict[str, Any],
                            truth: np.ndarray | None = None) -> None:
    """Write the figures of a :class:`~.pipeline.PoseEstimation` into ``folder``.

    Args:
        folder: Created when missing.
        result: The estimate.
        figures: The command's figures (``summary.json``).
        truth: ``(n, 3)`` ground-truth poses already aligned to the estimate's frame, or
            None.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from vbn_common.atomic import write_text_atomic

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    poses = result.base_poses
    station = result.stations
    n_st = int(station.max()) + 1
    first = np.array([np.flatnonzero(station == s)[0] for s in range(n_st)])
    place = poses[first, :2]
    fig, ax = plt.subplots(figsize=(8, 7))
    kept = np.asarray(result.kept_direction, bool)
    segments = {True: [], False: []}
    for k, pair in enumerate(result.pairs):
        if pair.has_direction and station[pair.i] != station[pair.j]:
            segments[bool(kept[k])].append(
                (place[station[pair.i]], place[station[pair.j]]))
    for flag, colour, label in ((True, '0.6', 'kept'), (False, 'tab:red', 'dropped')):
        lines = segments[flag]
        for a, b in lines:
            ax.plot([a[0], b[0]], [a[1], b[1]], color=colour, lw=0.4, alpha=0.7)
        ax.plot([], [], color=colour, lw=1, label=f'{len(lines)} pairs with a direction, '
                                                  f'{label}')
    ax.plot(place[:, 0], place[:, 1], ':', color='tab:blue', lw=0.8,
            label='odometry steps between places')
    ax.plot(place[:, 0], place[:, 1], '.', color='k', ms=3, label=f'{n_st} places')
    ax.set_aspect('equal')
    ax.set_xlabel('x in map (m)')
    ax.set_ylabel('y in map (m)')
    pieces = len(result.components)
    ax.set_title(f'View graph: {len(result.pairs)} measured pairs, {pieces} piece'
                 + ('s' if pieces != 1 else ''))
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / 'view_graph.png', dpi=110)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(8, 7))
    odometry = result.odometry_poses
    ax.plot(odometry[:, 0], odometry[:, 1], '-', color='tab:orange', lw=0.8,
            label='odometry')
    ax.plot(poses[:, 0], poses[:, 1], '-', color='tab:blue', lw=0.8, label='estimated')
    if truth is not None:
        ax.plot(truth[:, 0], truth[:, 1], '--', color='k', lw=0.6,
                label='ground truth (SE(2)-aligned)')
    ax.plot(poses[0, 0], poses[0, 1], 'o', color='tab:green', label='first image (map origin)')
    ax.set_aspect('equal')
    ax.set_xlabel('x in map (m)')
    ax.set_ylabel('y in map (m)')
    ax.set_title('Image positions: odometry against the estimate')
    ax.legend(loc='best', fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / 'trajectories.png', dpi=110)
    plt.close(fig)
    write_text_atomic(folder / 'summary.json', json.dumps(figures, indent=2, default=float))
