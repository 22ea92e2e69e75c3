"""Check any decomposition against its world (Definitions 3.4 to 3.8, Sections 5.1, 5.5).

A decomposition is valid when:

* every region is non-empty, its pose indices are in range and distinct, and it is
  connected in G (Definition 3.4);
* it lists exactly k distinct landmark feature ids, every one seen from every pose of
  the region (so at least k features are common to the region);
* every k-coverable pose (judged on the rho-reduced sets F~_v of Theorem 4.1 when
  rho > 0) is served, i.e. has its whole N_rho(v) inside one region (Definition 3.7,
  the rho-overlap property; :mod:`.service`), unless it is listed in ``uncovered``;
* every pose listed in ``uncovered`` is k-coverable and really not served;
* when sigma = 0, ``uncovered`` is empty (every algorithm here promises a complete
  decomposition then).
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import csgraph

from landmark_db.decomposition.model import Decomposition
from landmark_db.decomposition.service import service
from landmark_db.world import WorldInstance

__all__ = ['validate']

_MAX_REPORTED = 20


def validate(world: WorldInstance, decomposition: Decomposition) -> list[str]:
    """Return the problems of ``decomposition`` for ``world``; empty when valid.

    Args:
        world: the world instance the decomposition claims to decompose.
        decomposition: the decomposition to check.

    Returns:
        Human-readable problems, one per line (at most about 20 region problems are
        listed individually).
    """
    problems: list[str] = []
    k, rho, sigma = decomposition.k, decomposition.rho, decomposition.sigma
    if k < 1:
        problems.append(f'k must be at least 1, got {k}')
    if rho < 0:
        problems.append(f'rho must be non-negative, got {rho}')
    if sigma < 0:
        problems.append(f'sigma must be non-negative, got {sigma}')
    if problems:
        return problems
    n = world.n_poses
    region_problems: list[str] = []
    good_regions: list[np.ndarray] = []
    adjacency = world.adjacency
    csc = world.visible_csc
    for i, region in enumerate(decomposition.regions):
        poses = region.poses
        if poses.size == 0:
            region_problems.append(f'region {i} is empty')
            continue
        if poses.min() < 0 or poses.max() >= n:
            region_problems.append(f'region {i} has a pose index out of range (n = {n})')
            continue
        unique = np.unique(poses)
        if unique.size != poses.size:
            region_problems.append(f'region {i} lists a pose twice')
        n_comp = csgraph.connected_components(adjacency[unique][:, unique], directed=False)[0]
        if n_comp != 1:
            region_problems.append(f'region {i} is not connected ({n_comp} pieces)')
        features = region.features
        if features.size != k or np.unique(features).size != k:
            region_problems.append(
                f'region {i} lists {np.unique(features).size} distinct landmark features, '
                f'expected k = {k}')
        known = np.isin(features, world.feature_ids)
        if not known.all():
            region_problems.append(
                f'region {i} lists feature {int(features[~known][0])}, not in the world')
        else:
            cols = world.columns_of(features)
            for col, fid in zip(cols, features):
                seen = csc.indices[csc.indptr[col]:csc.indptr[col + 1]]
                blind = unique[~np.isin(unique, seen, assume_unique=True)]
                if blind.size:
                    region_problems.append(
                        f'region {i}: feature {int(fid)} is not visible from pose '
                        f'{int(blind[0])} (nor from {blind.size - 1} more of its '
                        f'{unique.size} poses)')
                    break
        good_regions.append(unique)
    problems.extend(region_problems[:_MAX_REPORTED])
    if len(region_problems) > _MAX_REPORTED:
        problems.append(f'... and {len(region_problems) - _MAX_REPORTED} more region problems')

    uncovered = decomposition.uncovered
    if uncovered.size and (uncovered.min() < 0 or uncovered.max() >= n):
        problems.append(f'uncovered lists a pose index out of range (n = {n})')
        return problems
    if np.unique(uncovered).size != uncovered.size:
        problems.append('uncovered lists a pose twice')
    measured = service(world, good_regions, k, rho)
    coverable, covered = measured.coverable_mask, measured.served_mask
    listed = np.zeros(n, dtype=bool)
    listed[uncovered] = True
    missing = np.flatnonzero(coverable & ~covered & ~listed)
    what = 'k-coverable' if rho == 0 else f'k-coverable (after the rho = {rho} reduction)'
    how = 'lie in no region' if rho == 0 else f'have their N_{rho} inside no single region'
    if missing.size:
        problems.append(f'{missing.size} {what} poses {how} and are not listed as uncovered, '
                        f'e.g. pose {int(missing[0])}')
    not_coverable = np.flatnonzero(listed & ~coverable)
    if not_coverable.size:
        problems.append(f'uncovered lists {not_coverable.size} poses that are not {what}, '
                        f'e.g. pose {int(not_coverable[0])}')
    falsely = np.flatnonzero(listed & covered)
    if falsely.size:
        problems.append(f'uncovered lists {falsely.size} poses that are covered, '
                        f'e.g. pose {int(falsely[0])}')
    if sigma == 0 and uncovered.size:
        problems.append(f'sigma = 0 requires a complete decomposition, but {uncovered.size} '
                        f'k-coverable poses are uncovered')
    return problems
