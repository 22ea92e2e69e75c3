"""Scaling run: decomposition time on large simulated worlds (up to 100,000 poses).

A scaling world is a setting-2-like world (rectangular, Type 2 features) grown to a
target pose count and feature count: a square perimeter of side ``s`` so that the
0.5 m grid has about ``n_poses`` poses, obstacles in the same density as setting 2
(about 8.5 per 1,600 m^2) and features spread along the walls at the density that
gives ``n_features`` in total.
"""
from __future__ import annotations

from dataclasses import replace
import logging
import math
import time
from typing import Any

import numpy as np

from landmark_db.defaults import POSE_SPACING, THESIS

__all__ = ['DEFAULT_SIZES', 'format_scaling', 'run_scaling', 'scaling_world']

_LOG = logging.getLogger(__name__)

DEFAULT_SIZES = ((5_000, 2_000), (20_000, 4_000), (50_000, 7_000), (100_000, 10_000))


def scaling_world(n_poses: int, n_features: int, seed: int = 0,
                  spacing: float = POSE_SPACING) -> Any:
    """Generate a world with about ``n_poses`` poses and exactly ``n_features`` features.

    Returns:
        A :class:`~vbn_worlds.simulator.simulate.SimulatedWorld`.
    """
    from landmark_db.scene import Scene
    from vbn_worlds.simulator.grid import pose_grid
    from vbn_worlds.simulator.scene_sampler import place_features, random_scene
    from vbn_worlds.simulator.settings import Mixture, get_setting
    from vbn_worlds.simulator.simulate import SimulatedWorld, world_from_scene

    base = get_setting(2)
    free_fraction = 0.93  # share of the square left after obstacles and wall margins
    side = math.sqrt(n_poses * spacing ** 2 / free_fraction)
    obstacles = 8.5 * side ** 2 / 1600.0
    shape = replace(base.shape, size_m=Mixture((('N', side, 0.0, 1.0),)),
                    obstacle_count=Mixture((('N', obstacles, 0.0, 1.0),)))
    setting = replace(base, shape=shape, number=2)
    rng = np.random.default_rng([seed, n_poses, n_features])
    bare = random_scene(replace(setting, features=replace(setting.features,
                                                          density_per_m=0.0)), rng)
    wall = sum(float(np.linalg.norm(np.roll(p, -1, axis=0) - p, axis=1).sum())
               for p in bare.polygons())
    usable = wall - 0.1 * sum(len(p) for p in bare.polygons())
    features = place_features(bare, replace(setting, features=replace(
        setting.features, density_per_m=n_features / usable)), rng)
    name = f'scaling-{n_poses}-{n_features}'
    scene = Scene(bare.perimeter, bare.obstacles, features, name=name)
    poses, edges = pose_grid(scene, spacing)
    return SimulatedWorld(scene, world_from_scene(scene, poses, edges, spacing, name))


def run_scaling(sizes: tuple[tuple[int, int], ...] = DEFAULT_SIZES,
                algorithms: tuple[str, ...] = ('B2',), k: int = THESIS.k,
                rho: int = THESIS.rho, sigma: int = THESIS.sigma, alpha: float = THESIS.alpha,
                seed: int = 0,
                progress: Any = None) -> list[dict[str, Any]]:
    """Time the algorithms on worlds of growing size.

    Args:
        sizes: ``(n_poses, n_features)`` targets.
        algorithms: algorithms to time on each world.
        k: features per landmark.
        rho: overlap radius.
        sigma: hole size below which no region is added.
        alpha: algorithm C's parameter.
        seed: world seed.
        progress: optional ``callable(row)`` after each run.

    Returns:
        One row per world and algorithm: sizes, mean visible count, world generation
        seconds, the algorithm's wall-clock and CPU seconds, regions and validator
        result.
    """
    from landmark_db.decomposition import decompose, validate

    rows = []
    for n_poses, n_features in sizes:
        start = time.perf_counter()
        simulated = scaling_world(n_poses, n_features, seed)
        simulate_seconds = time.perf_counter() - start
        world = simulated.world
        for algorithm in algorithms:
            row: dict[str, Any] = {
                'target_poses': n_poses, 'target_features': n_features,
                'poses': world.n_poses, 'features': world.n_features,
                'visible_pairs': int(world.visible.nnz),
                'mean_visible': simulated.mean_visible,
                'simulate_seconds': simulate_seconds, 'algorithm': algorithm}
            cpu_start = time.process_time()
            try:
                d = decompose(world, algorithm, k, rho=rho, sigma=sigma, alpha=alpha, rng=seed)
            except Exception as error:  # noqa: BLE001 - reported in the row
                row.update(seconds=float('nan'), cpu_seconds=float('nan'), regions=0,
                           valid=False, problems=[f'{type(error).__name__}: {error}'])
            else:
                cpu_seconds = time.process_time() - cpu_start
                problems = validate(world, d)
                row.update(seconds=d.seconds, cpu_seconds=cpu_seconds, regions=len(d.regions),
                           uncovered=int(len(d.uncovered)), valid=not problems,
                           problems=list(problems[:3]))
            rows.append(row)
            if progress is not None:
                progress(row)
    return rows


def format_scaling(rows: list[dict[str, Any]]) -> str:
    """Format :func:`run_scaling`'s rows as a text table."""
    lines = [f'Scaling run (setting-2-like worlds, k={THESIS.k}, rho={THESIS.rho}, '
             f'sigma={THESIS.sigma})',
             f"{'poses':>8} {'features':>8} {'visible/pose':>12} {'simulate s':>10} "
             f"{'algorithm':>9} {'wall s':>8} {'CPU s':>8} {'regions':>7} {'valid':>5}"]
    for r in rows:
        lines.append(f"{r['poses']:>8} {r['features']:>8} {r['mean_visible']:>12.1f} "
                     f"{r['simulate_seconds']:>10.1f} {r['algorithm']:>9} "
                     f"{r['seconds']:>8.2f} {r['cpu_seconds']:>8.2f} {r['regions']:>7} "
                     f"{str(r['valid']):>5}")
        if r.get('problems'):
            lines.append(f"    problems: {'; '.join(r['problems'])}")
    return '\n'.join(lines)
