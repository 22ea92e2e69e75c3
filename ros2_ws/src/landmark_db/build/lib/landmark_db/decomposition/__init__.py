"""Region decomposition: rho-MORDP through 0-MORDP (Chapters 3 to 5 of the thesis).

``decompose(world, algorithm, k, rho, sigma)`` reduces the instance to 0-MORDP
(Theorem 4.1, :mod:`.overlap`), runs one algorithm on it and expands the regions back
(Theorem 4.2). Algorithms, one module each:

======== =========================================== ==============================
name     what                                        module
======== =========================================== ==============================
A1 A2 A3 grow regions from seeds (Figure 5.1)        :mod:`.grow_regions`
B1 B2    shrink regions until k features (Fig. 5.2)  :mod:`.shrink_regions`
C        neighbourhood-seeded regions (Figure 5.3)   :mod:`.neighbourhood_seeds`
exact    optimum by set cover + HiGHS MILP           :mod:`.exact`
best     candidate pool + set cover (new heuristic)  :mod:`.best`
(bound)  certified lower bound by column generation  :mod:`.bound`
======== =========================================== ==============================

Every algorithm returns a list of :class:`~.problem.ZeroRegion` (poses and landmark
columns on the reduced instance). Shared rules (sigma rule of Section 5.5,
disconnected pieces, ties) live in :mod:`.problem`; redundancy elimination
(Section 5.4) in :mod:`.redundancy`; the minimum set cover used by exact and best in
:mod:`.set_cover`; the validator in :mod:`.validate`; the one coverage measure
(*service*: k-coverable poses whose rho-neighbourhood lies in one region) in
:mod:`.service`.
"""
from __future__ import annotations

from collections.abc import Callable
import logging
import math
import time
from typing import Any

import numpy as np

from landmark_db.decomposition.bound import LowerBound, lower_bound
from landmark_db.decomposition.model import (
    Decomposition,
    Region,
    load_decomposition,
    save_decomposition,
)
from landmark_db.decomposition.overlap import expand_region, neighbourhood_matrix
from landmark_db.decomposition.problem import ZeroProblem, ZeroRegion, zero_problem
from landmark_db.decomposition.service import Service, service
from landmark_db.decomposition.validate import validate
from landmark_db.defaults import DECOMPOSITION
from landmark_db.errors import LandmarkDbError
from landmark_db.world import WorldInstance

__all__ = [
    'ALGORITHMS',
    'Decomposition',
    'LowerBound',
    'Region',
    'Service',
    'certify',
    'decompose',
    'load_decomposition',
    'save_decomposition',
    'service',
    'validate',
]

ALGORITHMS = ('A1', 'A2', 'A3', 'B1', 'B2', 'C', 'exact', 'best')

_LOG = logging.getLogger(__name__)


def decompose(world: WorldInstance, algorithm: str, k: int, rho: int = DECOMPOSITION.rho,
              sigma: int = DECOMPOSITION.sigma, alpha: float = DECOMPOSITION.alpha,
              rng: Any = None, check_stop: Callable[[], None] | None = None,
              **options: Any) -> Decomposition:
    """Decompose a world into regions with k-feature landmarks (rho-MORDP).

    Args:
        world: the world instance.
        algorithm: one of :data:`ALGORITHMS`.
        k: features per landmark (>= 1).
        rho: overlap radius in graph steps (>= 0).
        sigma: a region is added only if it covers more than sigma otherwise
            uncovered poses (>= 0; Section 5.5).
        alpha: algorithm C's least unassigned fraction of N_r(v), in (0, 1].
        rng: ``numpy.random.Generator`` or seed for tie-breaking; None means
            ``DECOMPOSITION.seed`` (0).
        check_stop: Called between the steps of the longer searches (``best``'s
            algorithms, seeds and pricing rounds; before ``exact``); what it raises
            ends the decomposition (the builder node's shutdown).
        **options: passed to ``exact`` (``time_limit``, ``max_subsets``,
            ``max_candidates``) or ``best`` (``time_limit``, ``rounds``).

    Returns:
        The decomposition, in original pose indices and feature ids. ``uncovered``
        lists the k-coverable poses (on the rho-reduced sets) that no region covers
        with their whole N_rho; ``seconds`` includes the reduction and expansion.

    Raises:
        LandmarkDbError: on an unknown algorithm or out-of-range parameter, or when
            ``exact`` refuses the instance.

    Example:
        >>> import numpy as np
        >>> from landmark_db.world import grid_world
        >>> world = grid_world(3, 1, 0.5, np.array([[1, 1], [1, 1], [1, 0]], bool))
        >>> d = decompose(world, 'B2', k=1)
        >>> [r.poses.tolist() for r in d.regions], [r.features.tolist() for r in d.regions]
        ([[0, 1, 2]], [[0]])
    """
    if algorithm not in ALGORITHMS:
        raise LandmarkDbError(f'unknown algorithm {algorithm!r}; choose one of '
                              f'{", ".join(ALGORITHMS)}')
    k = _check_int(k, 'k', 1)
    rho = _check_int(rho, 'rho', 0)
    sigma = _check_int(sigma, 'sigma', 0)
    if isinstance(alpha, bool) or not isinstance(alpha, (int, float)) or \
            not math.isfinite(alpha) or not 0 < alpha <= 1:
        raise LandmarkDbError(f'alpha must be in (0, 1], got {alpha!r}')
    generator = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(
        DECOMPOSITION.seed if rng is None else rng)
    start = time.perf_counter()
    problem = zero_problem(world, k, rho, sigma, generator)
    certificate: dict[str, Any] = {}
    if check_stop is not None:
        check_stop()
    reduced = _run(problem, algorithm, float(alpha), options, certificate, check_stop) \
        if problem.coverable.any() else []
    hood = neighbourhood_matrix(world.adjacency, rho) if rho else None
    regions = []
    for region in reduced:
        expanded = expand_region(hood, region.poses) if hood is not None else region.poses
        regions.append(Region(expanded, world.feature_ids[np.sort(region.columns)]))
    uncovered = service(world, [region.poses for region in regions], k, rho,
                        coverable=problem.coverable, neighbourhoods=hood).unserved
    seconds = time.perf_counter() - start
    _LOG.debug('%s: %d regions, %d uncovered, %.3f s', algorithm, len(regions),
               uncovered.size, seconds)
    bound = certificate.get('bound')
    if algorithm == 'exact':
        lower = len(regions)  # proven optimal
    else:
        lower = bound.regions if bound is not None else None
    return Decomposition(algorithm, k, rho, sigma, seconds, regions, uncovered, lower)


def certify(world: WorldInstance, decomposition: Decomposition,
            **limits: Any) -> LowerBound:
    """Bound the regions of any complete decomposition of ``world`` from below.

    The decomposition's landmarks seed the pool of :func:`.bound.lower_bound`, which
    prices more candidates until the LP relaxation is solved (or its limits stop it;
    the bound is valid either way).

    Args:
        world: the world instance.
        decomposition: any decomposition of it (its k and rho are used).
        **limits: ``max_rounds``, ``node_limit`` of :func:`.bound.lower_bound`.
    """
    problem = zero_problem(world, decomposition.k, decomposition.rho, 0,
                           np.random.default_rng(DECOMPOSITION.seed))
    pool = []
    for region in decomposition.regions:
        known = np.isin(region.features, world.feature_ids)
        if region.features.size == decomposition.k and known.all():
            pool.append(ZeroRegion(region.poses, world.columns_of(region.features)))
    return lower_bound(problem, pool, **limits)


def _run(problem: ZeroProblem, algorithm: str, alpha: float,
         options: dict[str, Any], certificate: dict[str, Any],
         check_stop: Callable[[], None] | None = None) -> list[ZeroRegion]:
    if algorithm in ('A1', 'A2', 'A3'):
        from landmark_db.decomposition.grow_regions import grow_regions
        return grow_regions(problem, algorithm)
    if algorithm in ('B1', 'B2'):
        from landmark_db.decomposition.shrink_regions import shrink_regions
        return shrink_regions(problem, algorithm)
    if algorithm == 'C':
        from landmark_db.decomposition.neighbourhood_seeds import neighbourhood_seeds
        return neighbourhood_seeds(problem, alpha)
    if algorithm == 'exact':
        from landmark_db.decomposition.exact import exact_cover
        return exact_cover(problem, **options)
    from landmark_db.decomposition.best import best_cover
    return best_cover(problem, alpha=alpha, certificate=certificate, check_stop=check_stop,
                      **options)


def _check_int(value: Any, name: str, least: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
        raise LandmarkDbError(f'{name} must be an integer >= {least}, got {value!r}')
    return int(value)
