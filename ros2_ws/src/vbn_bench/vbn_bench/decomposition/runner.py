"""The decomposition benchmark of Section 8.2: many random worlds, every algorithm.

For each setting and world seed the runner simulates the world
(:func:`~vbn_worlds.simulator.simulate.simulate_world`), decomposes it with each
algorithm, checks every decomposition with :func:`~landmark_db.decomposition.validate`
and records Figure 8.3's statistics: the number of regions (Table 8.2), the mean
number of poses per region (Table 8.3), the number of distinct landmark features
used, the uncovered k-coverable poses and the algorithm's time (wall-clock, as
``Decomposition.seconds``, and the process's CPU time, which other programs' load on
the machine disturbs less). A second, optional
class of reduced-size worlds (:func:`~vbn_worlds.simulator.settings.small_setting`)
adds the exact optimum, so that every heuristic's approximation ratio is measured.

Worlds run in a process pool; each world's random generators depend only on
``(seed, setting, world index, algorithm)``, and results are collected in task order,
so every count is the same for any number of processes (only times vary).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
import logging
import multiprocessing
import time
from typing import Any

import numpy as np

from landmark_db.defaults import POSE_SPACING, THESIS

__all__ = ['WORLD_CLASS_LABELS', 'BenchConfig', 'RunRecord', 'WorldOutcome', 'decomposition_rng',
           'planned_worlds', 'records_as_dicts', 'run_benchmark', 'run_world']

_LOG = logging.getLogger(__name__)

FULL = 'full'  # full-size worlds of the main tables
REDUCED = 'reduced'  # reduced-size worlds of the main tables (quick runs, tests)
SMALL = 'small'  # reduced-size worlds of the approximation ratios (with the exact optimum)
WORLD_CLASS_LABELS = {FULL: 'worlds', REDUCED: 'worlds (reduced size)',
                      SMALL: 'small worlds (with exact)'}


@dataclass(frozen=True)
class BenchConfig:
    """What the benchmark runs.

    Attributes:
        settings: setting numbers (1-4).
        worlds: full-size worlds per setting (the thesis used 300).
        seed: base seed; world ``i`` of setting ``s`` is ``simulate_world(s, seed + i)``.
        algorithms: the algorithms of the main tables.
        k, rho, sigma, alpha: decomposition parameters (the thesis's, ``defaults.THESIS``).
        spacing: pose grid spacing, metres.
        reduced: run the main tables on reduced-size worlds (fast tests).
        small_worlds: reduced-size worlds per setting for the approximation ratios
            against the exact optimum (0 skips them).
        small_sigma: sigma for the small worlds; 0 by default, since the exact
            optimum is defined for complete decompositions.
        processes: worker processes (1 runs in this process).
        exact_max_subsets: the exact solver's limit on candidate landmarks.
        exact_max_candidates: the exact solver's limit on candidate regions.
        exact_time_limit: seconds HiGHS may take per small world.
    """

    settings: tuple[int, ...] = (1, 2, 3, 4)
    worlds: int = 300
    seed: int = 0
    algorithms: tuple[str, ...] = ('A1', 'A2', 'A3', 'B1', 'B2', 'C', 'best')
    k: int = THESIS.k
    rho: int = THESIS.rho
    sigma: int = THESIS.sigma
    alpha: float = THESIS.alpha
    spacing: float = POSE_SPACING
    reduced: bool = False
    small_worlds: int = 10
    small_sigma: int = 0
    processes: int = 2
    exact_max_subsets: int = 3_000_000
    exact_max_candidates: int = 500_000
    exact_time_limit: float = 120.0


@dataclass
class RunRecord:
    """One algorithm on one world."""

    world_class: str
    setting: int
    world_seed: int
    algorithm: str
    k: int
    rho: int
    sigma: int
    n_poses: int
    n_edges: int
    n_features: int
    mean_visible: float
    n_coverable: int
    regions: int = 0
    mean_region_poses: float = 0.0
    used_features: int = 0
    uncovered: int = 0
    seconds: float = 0.0
    cpu_seconds: float = 0.0
    valid: bool = False
    problems: list[str] = field(default_factory=list)


@dataclass
class WorldOutcome:
    """Everything one world task returns.

    Attributes:
        records: one record per algorithm.
        simulate_seconds: time to generate the world and its visibility.
        simulated: the world and scene, kept only when asked (for figures).
        decompositions: the decompositions by algorithm, kept only when asked.
    """

    records: list[RunRecord]
    simulate_seconds: float
    simulated: Any = None
    decompositions: dict[str, Any] | None = None


def decomposition_rng(seed: int, setting: int, world_seed: int,
                      algorithm: str) -> np.random.Generator:
    """Return the tie-breaking generator of one algorithm on one world."""
    code = sum((i + 1) * ord(c) for i, c in enumerate(algorithm))
    return np.random.default_rng([seed, setting, world_seed, code])


def run_world(task: tuple[Any, ...]) -> WorldOutcome:
    """Simulate one world and run every requested algorithm on it.

    Args:
        task: ``(config, world_class, setting, world_seed, algorithms, sigma, keep)``.

    Returns:
        The records (in ``algorithms`` order) and, if ``keep``, the world and the
        decompositions.
    """
    from landmark_db.decomposition import decompose, service, validate
    from vbn_worlds.simulator.settings import get_setting, small_setting
    from vbn_worlds.simulator.simulate import simulate_world

    config, world_class, setting_number, world_seed, algorithms, sigma, keep = task
    setting = get_setting(setting_number)
    if world_class in (SMALL, REDUCED):
        setting = small_setting(setting)
    start = time.perf_counter()
    simulated = simulate_world(setting, world_seed, spacing=config.spacing)
    simulate_seconds = time.perf_counter() - start
    world = simulated.world
    counts = np.asarray(world.visible_counts)
    base = dict(world_class=world_class, setting=setting_number, world_seed=world_seed,
                k=config.k, rho=config.rho, sigma=sigma, n_poses=world.n_poses,
                n_edges=int(len(world.edges)), n_features=world.n_features,
                mean_visible=float(counts.mean()) if counts.size else 0.0,
                n_coverable=service(world, [], config.k, config.rho).k_coverable)
    records = []
    kept: dict[str, Any] = {}
    for algorithm in algorithms:
        record = RunRecord(algorithm=algorithm, **base)
        rng = decomposition_rng(config.seed, setting_number, world_seed, algorithm)
        options = {}
        if algorithm == 'exact':
            options = {'max_subsets': config.exact_max_subsets,
                       'max_candidates': config.exact_max_candidates,
                       'time_limit': config.exact_time_limit}
        cpu_start = time.process_time()
        try:
            decomposition = decompose(world, algorithm, config.k, rho=config.rho, sigma=sigma,
                                      alpha=config.alpha, rng=rng, **options)
        except Exception as error:  # noqa: BLE001 - recorded and reported as a failure
            record.problems = [f'{type(error).__name__}: {error}']
            _LOG.error('%s world %s seed %d: %s raised %s', world_class, setting_number,
                       world_seed, algorithm, record.problems[0])
            records.append(record)
            continue
        record.cpu_seconds = time.process_time() - cpu_start
        sizes = [len(region.poses) for region in decomposition.regions]
        used = set()
        for region in decomposition.regions:
            used.update(int(f) for f in region.features)
        record.regions = len(sizes)
        record.mean_region_poses = float(np.mean(sizes)) if sizes else 0.0
        record.used_features = len(used)
        served = service(world, [region.poses for region in decomposition.regions],
                         config.k, config.rho)
        record.uncovered = int(served.unserved.size)
        record.seconds = float(decomposition.seconds)
        record.problems = list(validate(world, decomposition))
        record.valid = not record.problems
        if record.problems:
            _LOG.error('INVALID %s decomposition of %s world %s seed %d: %s', algorithm,
                       world_class, setting_number, world_seed, '; '.join(record.problems[:3]))
        records.append(record)
        if keep:
            kept[algorithm] = decomposition
    return WorldOutcome(records, simulate_seconds, simulated if keep else None,
                        kept if keep else None)


def _tasks(config: BenchConfig) -> list[tuple[Any, ...]]:
    tasks = []
    main_class = REDUCED if config.reduced else FULL
    for setting in config.settings:
        for index in range(config.worlds):
            tasks.append((config, main_class, setting, config.seed + index,
                          config.algorithms, config.sigma, index == 0))
    if config.small_worlds > 0:
        small_algorithms = tuple(dict.fromkeys((*config.algorithms, 'exact')))
        for setting in config.settings:
            for index in range(config.small_worlds):
                tasks.append((config, SMALL, setting, config.seed + index, small_algorithms,
                              config.small_sigma, False))
    return tasks


def planned_worlds(config: BenchConfig) -> dict[str, int]:
    """Return how many worlds of each class the benchmark runs, in running order.

    Returns:
        ``{FULL or REDUCED: settings x worlds, SMALL: settings x small_worlds}`` (the
        small class only when ``small_worlds > 0``).
    """
    counts: dict[str, int] = {}
    for task in _tasks(config):
        counts[task[1]] = counts.get(task[1], 0) + 1
    return counts


def run_benchmark(config: BenchConfig, progress: Any = None) -> tuple[list[RunRecord],
                                                                      dict[int, WorldOutcome]]:
    """Run the whole benchmark.

    Args:
        config: what to run.
        progress: optional ``callable(world_class, done, total)`` called after each
            world, counting within its class (main-table worlds and the small worlds
            of the approximation ratios separately, see :func:`planned_worlds`).

    Returns:
        ``(records, figure_worlds)``: all records in task order, and for each setting
        the first main-class world with its decompositions (for the figures).
    """
    tasks = _tasks(config)
    records: list[RunRecord] = []
    figure_worlds: dict[int, WorldOutcome] = {}
    if config.processes > 1 and len(tasks) > 1:
        context = multiprocessing.get_context('fork')
        with context.Pool(config.processes) as pool:
            outcomes = pool.imap(run_world, tasks, chunksize=1)
            _collect(tasks, outcomes, records, figure_worlds, progress)
    else:
        _collect(tasks, map(run_world, tasks), records, figure_worlds, progress)
    return records, figure_worlds


def _collect(tasks: list[tuple[Any, ...]], outcomes: Any, records: list[RunRecord],
             figure_worlds: dict[int, WorldOutcome], progress: Any) -> None:
    totals: dict[str, int] = {}
    for task in tasks:
        totals[task[1]] = totals.get(task[1], 0) + 1
    done: dict[str, int] = dict.fromkeys(totals, 0)
    for task, outcome in zip(tasks, outcomes):
        records.extend(outcome.records)
        if task[-1]:
            figure_worlds[task[2]] = outcome
        world_class = task[1]
        done[world_class] += 1
        if progress is not None:
            progress(world_class, done[world_class], totals[world_class])


def records_as_dicts(records: list[RunRecord]) -> list[dict[str, Any]]:
    """Return the records as JSON-ready dicts."""
    return [asdict(record) for record in records]
