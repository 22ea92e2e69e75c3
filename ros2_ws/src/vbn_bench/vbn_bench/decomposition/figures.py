"""PNG figures of the benchmark: Figure 8.3's bar chart and decomposition pictures."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from landmark_db.defaults import THESIS
from vbn_bench.decomposition.reference import THESIS_TABLE_8_2, THESIS_TABLE_8_3
from vbn_bench.decomposition.runner import FULL, WorldOutcome

__all__ = ['plot_bar_chart', 'plot_k_rho_sweep', 'plot_world_decompositions']


def plot_bar_chart(summary: dict[str, Any], algorithms: list[str], path: str | Path,
                   world_class: str = FULL) -> Path:
    """Draw Figure 8.3: regions, poses per region and used features per setting.

    Bars are our means per setting and algorithm (error bars: standard deviation of
    the region count); black ticks mark the thesis's Tables 8.2 and 8.3.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from vbn_common.palette import region_colours

    cells = {(c['setting'], c['algorithm']): c for c in summary['cells']
             if c['world_class'] == world_class}
    settings = sorted({s for s, _ in cells})
    colours = region_colours(len(algorithms), seed=3)
    width = 0.8 / max(1, len(algorithms))
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    panels = (('regions', 'Number of regions', THESIS_TABLE_8_2),
              ('poses_per_region', 'Poses per region', THESIS_TABLE_8_3),
              ('used_features', 'Used features', None))
    x = np.arange(len(settings))
    for ax, (key, title, table) in zip(axes, panels):
        for j, alg in enumerate(algorithms):
            values = [cells.get((s, alg), {}).get(key, np.nan) for s in settings]
            err = ([cells.get((s, alg), {}).get('regions_std', np.nan) for s in settings]
                   if key == 'regions' else None)
            offset = x - 0.4 + width * (j + 0.5)
            ax.bar(offset, values, width, yerr=err, color=colours[j], label=alg,
                   edgecolor='black', linewidth=0.4, error_kw={'elinewidth': 0.6})
            if table is not None:
                refs = [table.get(s, {}).get(alg, np.nan) for s in settings]
                ax.scatter(offset, refs, marker='_', s=120, c='black', linewidths=1.5,
                           zorder=5, label='thesis' if j == 0 else None)
        ax.set_xticks(x, [f'Setting {s}' for s in settings])
        ax.set_title(title)
        ax.grid(axis='y', alpha=0.3)
    axes[0].legend(fontsize=8, ncol=2)
    worlds = sorted({c['runs'] for c in cells.values()})
    fig.suptitle(f'Decomposition of synthetic worlds (k={THESIS.k}, rho={THESIS.rho}, '
                 f'sigma={THESIS.sigma}; '
                 f'{worlds[0] if worlds else 0} worlds per setting; black ticks: thesis)',
                 fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_world_decompositions(outcome: WorldOutcome, algorithms: list[str], path: str | Path,
                              k: int) -> Path:
    """Draw one world decomposed by each algorithm, one panel per algorithm.

    Like Figures 8.8 to 8.15: regions over the floor plan, one colour per region,
    uncovered k-coverable poses as black crosses.

    Returns:
        The path written.
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from visibility_builder.plotting import draw_decomposition

    simulated = outcome.simulated
    decompositions = outcome.decompositions or {}
    shown = [a for a in algorithms if a in decompositions]
    cols = min(4, max(1, len(shown)))
    rows = int(np.ceil(len(shown) / cols)) if shown else 1
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 4.2 * rows), squeeze=False)
    for ax in axes.ravel():
        ax.set_visible(False)
    for ax, alg in zip(axes.ravel(), shown):
        ax.set_visible(True)
        d = decompositions[alg]
        draw_decomposition(ax, simulated.world, d.regions, k, d.uncovered,
                           scene=simulated.scene,
                           title=f'{alg}: {len(d.regions)} regions, '
                                 f'{len(d.uncovered)} uncovered')
    fig.suptitle(f'{simulated.world.name}: {simulated.world.n_poses} poses, '
                 f'{simulated.world.n_features} features', fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_k_rho_sweep(simulated: Any, path: str | Path, algorithm: str = 'B2',
                     ks: tuple[int, ...] = (4, 6, 8, 10), rhos: tuple[int, ...] = (0, 1),
                     sigma: int = 3, seed: int = 0) -> tuple[Path, list[dict[str, Any]]]:
    """Decompose one world for several k and rho, like Figures 8.8 to 8.15.

    The thesis shows B.2 on its 6 m x 3 m real world for k = 4, 6, 8, 10 and
    rho = 0, 1 with sigma = 3; this draws the same sweep on a simulated world, one
    panel per (k, rho), every decomposition checked by the validator.

    Returns:
        The path written and one row per panel (k, rho, regions, uncovered, problems).
    """
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from landmark_db.decomposition import decompose, validate
    from visibility_builder.plotting import draw_decomposition

    world = simulated.world
    fig, axes = plt.subplots(len(rhos), len(ks), figsize=(4.2 * len(ks), 4.2 * len(rhos)),
                             squeeze=False)
    rows = []
    for i, rho in enumerate(rhos):
        for j, k in enumerate(ks):
            try:
                d = decompose(world, algorithm, k, rho=rho, sigma=sigma, rng=seed)
            except Exception as error:  # noqa: BLE001 - reported in the row and the panel
                message = f'{type(error).__name__}: {error}'
                rows.append({'k': k, 'rho': rho, 'regions': 0, 'uncovered': 0,
                             'problems': [message]})
                axes[i, j].set_title(f'{algorithm}, k={k}, rho={rho}: FAILED', fontsize=9)
                axes[i, j].text(0.5, 0.5, message[:80], ha='center', va='center', wrap=True,
                                transform=axes[i, j].transAxes, fontsize=7)
                continue
            problems = validate(world, d)
            rows.append({'k': k, 'rho': rho, 'regions': len(d.regions),
                         'uncovered': int(len(d.uncovered)), 'problems': list(problems)})
            mark = '' if not problems else ' INVALID'
            draw_decomposition(axes[i, j], world, d.regions, k, d.uncovered,
                               scene=simulated.scene,
                               title=f'{algorithm}, k={k}, rho={rho}, sigma={sigma}: '
                                     f'{len(d.regions)} regions{mark}')
    fig.suptitle(f'{world.name}: {world.n_poses} poses, {world.n_features} features '
                 '(compare thesis Figures 8.8-8.15)', fontsize=11)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path, rows
