"""Exact optimum of 0-MORDP as a minimum set cover (new; the thesis's future work).

Any region R of a decomposition has a landmark L (k features seen from all of R), and
R, being connected, lies inside one connected component of {v : L subset of F_v}.
Replacing every region by that component keeps the decomposition valid and its size
unchanged. So an optimum 0-MORDP decomposition is a minimum set cover of the
k-coverable poses by the *maximal candidate regions*: the connected components of
{v : L subset of F_v} over all k-subsets L of features seen together somewhere
(every such L is a k-subset of some F_v). The cover is solved as a 0/1 integer
program with SciPy's HiGHS (:mod:`.set_cover`); identical rows (poses lying in
exactly the same candidates) are merged first.

Under rho > 0 the same runs on the reduced instance (Theorem 4.1) and expands back
(Theorem 4.2), which preserves optimality. The optimum is that of the *complete*
decomposition: sigma does not apply (``uncovered`` is empty), so approximation ratios
should be measured against heuristics run with sigma = 0.

Refusals (``LandmarkDbError``): more than ``max_subsets`` candidate landmarks
(sum over poses of C(|F~_v|, k)), more than ``max_candidates`` candidate regions, or
no proven optimum within ``time_limit`` seconds.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from landmark_db.decomposition.problem import ZeroProblem, ZeroRegion, split_components
from landmark_db.decomposition.set_cover import solve_set_cover
from landmark_db.defaults import DECOMPOSITION
from landmark_db.errors import LandmarkDbError

__all__ = ['candidate_regions', 'exact_cover']

MAX_SUBSETS = 200_000
MAX_CANDIDATES = 50_000


def candidate_regions(problem: ZeroProblem, max_subsets: int = MAX_SUBSETS,
                      max_candidates: int = MAX_CANDIDATES,
                      ) -> list[ZeroRegion]:
    """Enumerate the maximal candidate regions of a 0-MORDP instance.

    Returns:
        Distinct regions, one per connected component of {v : L subset of F~_v} over
        all k-subsets L seen together somewhere (pose sets differ).

    Raises:
        LandmarkDbError: when the enumeration would exceed the limits.
    """
    k = problem.k
    rows = np.flatnonzero(problem.coverable)
    total = sum(math.comb(int(c), k) for c in problem.counts[rows])
    if total > max_subsets:
        raise LandmarkDbError(
            f'exact solver refused: {total} candidate landmarks (k-subsets of visibility '
            f'sets) exceed the limit of {max_subsets}; use a smaller world or k')
    subsets: set[tuple[int, ...]] = set()
    for v in rows:
        subsets.update(itertools.combinations(problem.row_features(int(v)).tolist(), k))
    masks = {}
    for col in {c for subset in subsets for c in subset}:
        bits = np.zeros(problem.n_poses, dtype=np.uint8)
        bits[problem.column_poses(col)] = 1
        masks[col] = int.from_bytes(np.packbits(bits, bitorder='little').tobytes(), 'little')
    pose_sets: dict[int, tuple[int, ...]] = {}
    for subset in sorted(subsets):
        mask = masks[subset[0]]
        for col in subset[1:]:
            mask &= masks[col]
        pose_sets.setdefault(mask, subset)
    candidates: dict[bytes, ZeroRegion] = {}
    n_bytes = (problem.n_poses + 7) // 8
    for mask, subset in pose_sets.items():
        bits = np.unpackbits(np.frombuffer(mask.to_bytes(n_bytes, 'little'), dtype=np.uint8),
                             bitorder='little')
        poses = np.flatnonzero(bits[:problem.n_poses]).astype(np.int64)
        for piece in split_components(problem.adjacency, poses):
            key = piece.tobytes()
            if key not in candidates:
                candidates[key] = ZeroRegion(piece, np.asarray(subset, dtype=np.int64))
                if len(candidates) > max_candidates:
                    raise LandmarkDbError(
                        f'exact solver refused: more than {max_candidates} candidate '
                        f'regions; use a smaller world or k')
    return list(candidates.values())


def exact_cover(problem: ZeroProblem, time_limit: float = DECOMPOSITION.exact_time_limit,
                max_subsets: int = MAX_SUBSETS,
                max_candidates: int = MAX_CANDIDATES) -> list[ZeroRegion]:
    """Return an optimum 0-MORDP decomposition (complete cover, sigma ignored).

    Raises:
        LandmarkDbError: when the instance is too large (see the module docstring).
    """
    required = np.flatnonzero(problem.coverable)
    if required.size == 0:
        return []
    candidates = candidate_regions(problem, max_subsets, max_candidates)
    chosen, optimal = solve_set_cover(problem.n_poses, required,
                                      [c.poses for c in candidates], time_limit)
    if not optimal:
        raise LandmarkDbError(
            f'exact solver: HiGHS did not prove optimality within {time_limit:g} s '
            f'({len(candidates)} candidate regions)')
    return [candidates[i] for i in chosen]
