"""Calibration of the feature density against Table 8.4 (features visible per pose).

The thesis does not give the number of features per world. The expected number of
features visible from a pose grows linearly with the feature density along the walls
(every feature's visibility area is independent of the others), so one run at the
current density gives the density that meets Table 8.4's target:
``density x target / measured``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from landmark_db.defaults import POSE_SPACING
from vbn_bench.decomposition.reference import THESIS_TABLE_8_4

__all__ = ['calibrate', 'format_calibration']


def _measure(task: tuple[int, int, float]) -> dict[str, Any]:
    from vbn_worlds.simulator.settings import get_setting
    from vbn_worlds.simulator.simulate import simulate_world

    setting, seed, spacing = task
    simulated = simulate_world(get_setting(setting), seed, spacing=spacing)
    scene = simulated.scene
    wall = sum(float(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1).sum())
               for p in scene.polygons())
    return {'setting': setting, 'seed': seed, 'mean_visible': simulated.mean_visible,
            'poses': simulated.world.n_poses, 'features': simulated.world.n_features,
            'wall_m': wall, 'obstacles': len(scene.obstacles)}


def calibrate(settings: tuple[int, ...] = (1, 2, 3, 4), worlds: int = 20, seed: int = 0,
              spacing: float = POSE_SPACING, processes: int = 2) -> list[dict[str, Any]]:
    """Measure the mean visible count per setting and the density that meets Table 8.4.

    Args:
        settings: setting numbers.
        worlds: worlds per setting (seeds ``seed .. seed + worlds - 1``).
        seed: first seed.
        spacing: pose grid spacing, metres.
        processes: worker processes.

    Returns:
        One dict per setting: current density, measured mean (and standard deviation
        over worlds) of features visible per pose, Table 8.4's target, the suggested
        density, and the mean pose, feature, obstacle and wall-length counts.
    """
    import multiprocessing

    from vbn_worlds.simulator.settings import get_setting

    tasks = [(s, seed + i, spacing) for s in settings for i in range(worlds)]
    if processes > 1:
        with multiprocessing.get_context('fork').Pool(processes) as pool:
            rows = pool.map(_measure, tasks, chunksize=1)
    else:
        rows = [_measure(t) for t in tasks]
    out = []
    for s in settings:
        mine = [r for r in rows if r['setting'] == s]
        means = np.array([r['mean_visible'] for r in mine])
        density = get_setting(s).features.density_per_m
        target = THESIS_TABLE_8_4[s]
        out.append({
            'setting': s, 'worlds': len(mine), 'density_per_m': density,
            'mean_visible': float(means.mean()), 'mean_visible_std': float(means.std()),
            'target': target, 'suggested_density_per_m': density * target / means.mean(),
            'poses': float(np.mean([r['poses'] for r in mine])),
            'features': float(np.mean([r['features'] for r in mine])),
            'obstacles': float(np.mean([r['obstacles'] for r in mine])),
            'wall_m': float(np.mean([r['wall_m'] for r in mine])),
        })
    return out


def format_calibration(rows: list[dict[str, Any]]) -> str:
    """Format :func:`calibrate`'s result as a text table."""
    lines = ['Feature-density calibration against Table 8.4 (features visible per pose)',
             f"{'setting':>7} {'worlds':>6} {'density/m':>9} {'measured':>14} {'Table 8.4':>9} "
             f"{'suggested/m':>11} {'poses':>7} {'features':>8} {'obstacles':>9} {'wall m':>7}"]
    for r in rows:
        lines.append(
            f"{r['setting']:>7} {r['worlds']:>6} {r['density_per_m']:>9.3f} "
            f"{r['mean_visible']:>8.1f} +-{r['mean_visible_std']:>4.1f} {r['target']:>9} "
            f"{r['suggested_density_per_m']:>11.3f} {r['poses']:>7.0f} {r['features']:>8.0f} "
            f"{r['obstacles']:>9.1f} {r['wall_m']:>7.0f}")
    return '\n'.join(lines)
