"""A certified lower bound on the fewest regions (new; where :mod:`.exact` cannot enumerate).

An optimum 0-MORDP decomposition is a minimum set cover of the k-coverable poses by
the maximal candidate regions (:mod:`.exact`): the connected components of
{v : L subset of F~_v} over the k-subsets L. On built worlds there are far too many
to list (about 1.8e11 candidate landmarks on the room), so the bound works on the
linear relaxation of that cover and never lists them:

1. **Restricted master.** The LP relaxation min sum x_S, sum_{S containing v} x_S >= 1
   over a pool of candidates (the decomposition's own landmarks and their components)
   is solved with HiGHS (``scipy.optimize.linprog``); its duals y_v >= 0 price the poses.
2. **Pricing** (column generation, :mod:`.pricing`): the candidate S maximising
   y(S) = sum over v in S of y_v, searched anchor by anchor (each candidate of positive
   weight holds a pose of positive dual) by branch and bound over the supports
   {v : C subset of F~_v} of growing feature sets C, each cut to the anchor's
   component; a support bounds everything below it, and so does the (k - |closure|)-th
   heaviest of its one-feature cuts. Candidates with y(S) > 1 join the pool and the
   master is solved again.
3. **Certificate.** For any duals y and any U >= max_S y(S) over *all* candidates,
   y / U is feasible for the dual of the full LP, so sum(y) / U is a lower bound on the
   LP optimum and its ceiling one on the optimum decomposition (weak duality; the
   Lagrangian bound of Farley, "A note on bounding a class of linear programming
   problems", Oper. Res. 38(5), 1990). When a search stops at its node limit, the
   weights of its open nodes enter U, so the bound stays valid however early it stops.

Under rho > 0 the bound is computed on the reduced instance (Theorem 4.1), whose
optimum equals that of rho-MORDP (Theorem 4.2). The bound is for a *complete*
decomposition (every k-coverable pose served), as the exact optimum is.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import logging
import math
import time

import numpy as np
from scipy.optimize import linprog
import scipy.sparse as sp

from landmark_db.decomposition.pricing import AnchoredPricing
from landmark_db.decomposition.problem import (
    ZeroProblem,
    ZeroRegion,
    component_of,
    split_components,
)
from landmark_db.decomposition.set_cover import cover_matrix, merge_identical_rows
from landmark_db.errors import LandmarkDbError

__all__ = ['LowerBound', 'lower_bound']

_EPS = 1e-9
_LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class LowerBound:
    """A certified lower bound on the fewest regions of a complete decomposition.

    Attributes:
        regions: the bound, an integer: no complete decomposition has fewer regions.
        lp_value: the restricted master's LP optimum at the last round (an upper bound
            on the full LP's optimum).
        lp_bound: sum(y) / U, the certified lower bound on the full LP's optimum.
        columns: candidates in the final pool.
        rounds: pricing rounds run.
        proven: True when the last pricing round found no candidate with y(S) > 1
            (the LP relaxation is then solved exactly: ``lp_bound == lp_value``).
        seconds: wall-clock time.
    """

    regions: int
    lp_value: float
    lp_bound: float
    columns: int
    rounds: int
    proven: bool
    seconds: float

    def ratio(self, regions: int) -> float:
        """Return a decomposition's region count over the bound (1.0 is optimal)."""
        return regions / self.regions if self.regions else float('inf') if regions else 1.0


def lower_bound(problem: ZeroProblem, pool: list[ZeroRegion], max_rounds: int = 40,
                node_limit: int = 50_000, total_nodes: int = 400_000,
                columns_out: list[ZeroRegion] | None = None,
                check_stop: Callable[[], None] | None = None) -> LowerBound:
    """Bound the fewest regions of a complete decomposition of ``problem`` from below.

    Args:
        problem: the 0-MORDP instance.
        pool: starting candidates (any regions seeing their landmark; each is widened
            to its maximal candidate).
        max_rounds: most pricing rounds.
        node_limit: most branch-and-bound nodes per pricing round (limits, not
            seconds, keep the result the same on any machine).
        total_nodes: most nodes over all rounds; no round starts past it.
        columns_out: if given, receives every candidate of the final pool (maximal
            candidates, each with its landmark), for a set cover over them.
        check_stop: Called each round and every 1,024 branch-and-bound nodes; what
            it raises ends the search.

    Returns:
        The bound.

    Raises:
        LandmarkDbError: when some k-coverable pose lies in no candidate at all.
    """
    start = time.perf_counter()
    required = np.flatnonzero(problem.coverable)
    if required.size == 0:
        return LowerBound(0, 0.0, 0.0, 0, 0, True, time.perf_counter() - start)
    columns = _Columns(problem)
    for region in pool:
        columns.add_landmark(region.columns)
    columns.fill(required)
    rounds, proven, spent = 0, False, 0
    lp_value, lp_bound = 0.0, 0.0
    pricing = AnchoredPricing(problem)
    while True:
        lp_value, duals = _master(problem, required, columns.poses)
        total = float(duals.sum())
        if check_stop is not None:
            check_stop()
        priced = pricing.price(duals, min(node_limit, total_nodes - spent),
                               check_stop=check_stop)
        found, upper, proven, used = priced.regions, priced.upper, priced.proven, priced.nodes
        spent += used
        rounds += 1
        lp_bound = max(lp_bound, total / upper)
        added = sum(columns.add(region) for region in found)
        _LOG.debug('bound round %d: LP %.3f, U %.4f, bound %.3f, %d nodes, %d new columns '
                   '(%d in all), %.1f s', rounds, lp_value, upper, total / upper, used, added,
                   len(columns.regions), time.perf_counter() - start)
        if proven or not added:
            break
        if rounds >= max_rounds or spent >= total_nodes:
            break
    if columns_out is not None:
        columns_out.extend(columns.regions)
    return LowerBound(int(math.ceil(lp_bound - 1e-6)), lp_value, lp_bound,
                      len(columns.poses), rounds, proven, time.perf_counter() - start)


class _Columns:
    """The master's candidate pool: distinct maximal candidates."""

    def __init__(self, problem: ZeroProblem) -> None:
        self.problem = problem
        self.regions: list[ZeroRegion] = []
        self._seen: set[bytes] = set()
        self._landmarks: set[bytes] = set()

    @property
    def poses(self) -> list[np.ndarray]:
        """The candidates' pose sets, in pool order."""
        return [region.poses for region in self.regions]

    def add(self, region: ZeroRegion) -> bool:
        key = region.poses.tobytes()
        if key in self._seen:
            return False
        self._seen.add(key)
        self.regions.append(region)
        return True

    def add_landmark(self, columns: np.ndarray) -> None:
        landmark = np.sort(np.asarray(columns, dtype=np.int64))
        key = landmark.tobytes()
        if key in self._landmarks:
            return
        self._landmarks.add(key)
        for piece in split_components(self.problem.adjacency,
                                      self.problem.poses_seeing_all(landmark)):
            self.add(ZeroRegion(piece, landmark))

    def fill(self, required: np.ndarray) -> None:
        """Give every required pose a candidate: k of its features, most seen first."""
        problem = self.problem
        covered = np.zeros(problem.n_poses, dtype=bool)
        for poses in self.poses:
            covered[poses] = True
        sizes = np.diff(problem.visible_csc.indptr)
        for v in required[~covered[required]]:
            if covered[v]:
                continue
            cols = problem.row_features(int(v))
            landmark = np.sort(cols[np.argsort(-sizes[cols], kind='stable')[:problem.k]])
            region = component_of(problem.adjacency, problem.poses_seeing_all(landmark), int(v))
            self.add(ZeroRegion(region, landmark))
            covered[region] = True


def _master(problem: ZeroProblem, required: np.ndarray,
            sets: list[np.ndarray]) -> tuple[float, np.ndarray]:
    """Solve the restricted LP; return its value and per-pose duals (length n)."""
    matrix = cover_matrix(problem.n_poses, required, sets)
    if (np.diff(matrix.indptr) == 0).any():
        raise LandmarkDbError('lower bound: a k-coverable pose lies in no candidate')
    merged, members = merge_identical_rows(matrix)
    result = linprog(np.ones(len(sets)), A_ub=-sp.csr_matrix(merged),
                     b_ub=-np.ones(merged.shape[0]), bounds=(0, None), method='highs')
    if result.status != 0:
        raise LandmarkDbError(f'lower bound: the LP failed ({result.message})')
    group_duals = np.maximum(-np.asarray(result.ineqlin.marginals), 0.0)
    duals = np.zeros(problem.n_poses)
    for value, rows in zip(group_duals, members):
        # Spread a merged row's dual over its poses: every pool column holds all of
        # them or none, so the pool's column sums are unchanged.
        duals[required[rows]] = value / rows.size
    return float(result.fun), duals
