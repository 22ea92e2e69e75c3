"""Minimum set cover of poses by candidate regions, exact (MILP) and relaxed (LP).

**Problem.** Given a universe U of required poses and a family S_1, ..., S_m of pose
sets (candidate regions), choose the fewest sets whose union contains U (minimum set
cover). The *budgeted partial* variant allows at most b poses of U to stay uncovered.
The exact solver (:mod:`.exact`, every maximal candidate region) and the heuristic
``best`` (:mod:`.best`, a pool of them) both reduce 0-MORDP to this problem.

**Reference.** Set cover is one of Karp's 21 NP-complete problems (R. M. Karp,
"Reducibility among combinatorial problems", 1972); the greedy algorithm is an
H(max |S_j|)-approximation (V. Chvatal, "A greedy heuristic for the set-covering
problem", Math. Oper. Res. 4(3), 1979). Here it is solved as a 0/1 integer program
by HiGHS (Q. Huangfu and J. A. J. Hall, "Parallelizing the dual revised simplex
method", Math. Prog. Comp. 10, 2018) through ``scipy.optimize.milp``, and its LP
relaxation through ``scipy.optimize.linprog``.

**Reductions** before the MILP (the classic ones of set-cover presolve; E. Balas and
M. W. Padberg, "Set partitioning: a survey", SIAM Review 18(4), 1976): a set contained
in another is never needed (with unit costs the larger one does its job), and a pose
whose sets all hold another pose is covered whenever that pose is (complete cover
only). They keep the optimum and shrink the program: on the room's 812 candidates x
185 pose patterns to 430 x 153, which HiGHS solves at the root in 0.8 s instead of
5 s and 14 nodes. That also keeps ``best`` off its time limit on a busy machine,
where the result would depend on the machine's speed.

**Complexity.** Building the incidence matrix costs O(sum |S_j|) and merging identical
rows (poses lying in exactly the same sets, interchangeable in any cover) O(nnz). A
dominance round costs the sparse products A^T A and A A^T, O(sum over rows of
nnz(row)^2) and O(sum over sets of |S_j|^2); it is skipped past ``DOMINANCE_MAX_WORK``.
The MILP is NP-hard, exponential in the worst case; callers bound it with a node limit
(and a time limit as a safety net). The LP relaxation is solved in polynomial time.
"""
from __future__ import annotations

import heapq
import logging
import time

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, linprog, milp
import scipy.sparse as sp

from landmark_db.errors import LandmarkDbError

__all__ = ['DOMINANCE_MAX_WORK', 'cover_matrix', 'greedy_partial_cover', 'merge_identical_rows',
           'reduce_by_dominance', 'relaxed_uncovered', 'solve_set_cover']

_LOG = logging.getLogger(__name__)

#: Most entries of the products a dominance round may form (above it the MILP is given
#: the matrix as it is).
DOMINANCE_MAX_WORK = 20_000_000


def cover_matrix(n_poses: int, required: np.ndarray, sets: list[np.ndarray]) -> sp.csr_matrix:
    """Return the set-cover incidence matrix of ``required`` poses by candidate ``sets``.

    Args:
        n_poses: number of poses (pose indices are below it).
        required: sorted poses to cover; row ``r`` is pose ``required[r]``.
        sets: pose index arrays (the candidate regions); column ``j`` is ``sets[j]``.

    Returns:
        ``(len(required), len(sets))`` CSR matrix of ones with sorted indices; poses of
        a set that are not required are left out.
    """
    sizes = np.array([s.size for s in sets], dtype=np.int64)
    row_index = np.full(n_poses, -1, dtype=np.int64)
    row_index[required] = np.arange(required.size)
    flat = np.concatenate(sets)
    cols = np.repeat(np.arange(len(sets)), sizes)
    keep = row_index[flat] >= 0
    matrix = sp.csr_matrix((np.ones(int(keep.sum())), (row_index[flat[keep]], cols[keep])),
                           shape=(required.size, len(sets)))
    matrix.sum_duplicates()
    matrix.sort_indices()
    return matrix


def merge_identical_rows(matrix: sp.csr_matrix) -> tuple[sp.csr_matrix, list[np.ndarray]]:
    """Merge the rows of a sorted-index CSR matrix that have the same column pattern.

    Poses covered by exactly the same candidates are interchangeable in a cover, so
    the integer program needs one row per pattern, weighted by its pose count.

    Returns:
        The merged matrix (one row per pattern, in order of first occurrence) and,
        per merged row, the indices of the original rows it stands for.
    """
    groups: dict[bytes, list[int]] = {}
    for r in range(matrix.shape[0]):
        groups.setdefault(matrix.indices[matrix.indptr[r]:matrix.indptr[r + 1]].tobytes(),
                          []).append(r)
    members = [np.array(rows, dtype=np.int64) for rows in groups.values()]
    first = np.array([rows[0] for rows in members], dtype=np.int64)
    return matrix[first], members


def reduce_by_dominance(matrix: sp.csr_matrix, rows: bool = True
                        ) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """Remove dominated sets (columns) and, if ``rows``, implied poses (rows).

    A column whose rows all lie in another column is dominated (of two equal columns
    the lower index stays). A row whose columns all cover another row is implied: any
    cover of the other covers it (of two equal rows the lower index stays). Rounds
    repeat until nothing changes. Removing rows is valid for the complete cover only,
    not for a budgeted one (where an implied pose may be one of those left out).

    Args:
        matrix: ``(rows x sets)`` 0/1 incidence matrix.
        rows: whether implied rows are removed too.

    Returns:
        ``(reduced matrix, kept column indices, kept row indices)``; an optimum cover
        of the reduced matrix, mapped through the kept columns, is one of the original.
    """
    a = sp.csr_matrix(matrix, dtype=np.int64)
    a.data[:] = 1
    cols = np.arange(a.shape[1])
    kept_rows = np.arange(a.shape[0])
    while True:
        row_nnz = np.diff(a.indptr)
        col_nnz = np.bincount(a.indices, minlength=a.shape[1])
        if int(row_nnz @ row_nnz) + int(col_nnz @ col_nnz) > DOMINANCE_MAX_WORK:
            break
        changed = False
        dominated = _contained(a.T.tocsr() @ a, col_nnz)
        if dominated.size:
            keep = np.setdiff1d(np.arange(a.shape[1]), dominated)
            a, cols, changed = a[:, keep].tocsr(), cols[keep], True
            row_nnz = np.diff(a.indptr)
        if rows:
            # Row j is implied when some row i has cols(i) inside cols(j): the row is the
            # containing one here, so transpose the containment.
            implied = _containing(a @ a.T.tocsr(), row_nnz)
            if implied.size:
                keep = np.setdiff1d(np.arange(a.shape[0]), implied)
                a, kept_rows, changed = a[keep], kept_rows[keep], True
        if not changed:
            break
    a.sort_indices()
    return a, cols, kept_rows


def _contained(overlap: sp.spmatrix, size: np.ndarray) -> np.ndarray:
    """Return the items i lying inside some other item j (of equal items the lowest stays)."""
    o = overlap.tocoo()
    i, j = o.row, o.col
    inside = (o.data == size[i]) & (i != j) & ((size[j] > size[i]) | (j < i))
    return np.unique(i[inside])


def _containing(overlap: sp.spmatrix, size: np.ndarray) -> np.ndarray:
    """Return the items j holding some other item i (of equal items the lowest stays)."""
    o = overlap.tocoo()
    i, j = o.row, o.col
    inside = (o.data == size[i]) & (i != j) & ((size[j] > size[i]) | (i < j))
    return np.unique(j[inside])


def solve_set_cover(n_poses: int, required: np.ndarray, sets: list[np.ndarray],
                    time_limit: float | None = None,
                    budget: int | None = None,
                    relative_gap: float | None = None,
                    node_limit: int | None = None) -> tuple[np.ndarray, bool]:
    """Solve a minimum set cover of ``required`` poses with HiGHS.

    Without ``budget``: min |C| such that every required pose lies in a chosen set.
    With ``budget``: a partial cover, min |C| such that at most ``budget`` required
    poses are left uncovered (ties go to the cover leaving fewer uncovered); ``best``
    uses this to cover at least as many poses as B.2 does under sigma.

    Args:
        n_poses: number of poses.
        required: sorted poses to cover.
        sets: sorted pose index arrays (the candidate regions).
        time_limit: seconds for HiGHS, or None for no limit.
        budget: most required poses that may stay uncovered, or None for none.
        relative_gap: stop once the incumbent is within this relative gap of the
            bound (None: HiGHS's default, i.e. prove optimality).
        node_limit: most branch-and-bound nodes; unlike a time limit it keeps the
            result independent of the machine's speed.

    Returns:
        (indices of the chosen sets, whether HiGHS proved the choice optimal).

    Raises:
        LandmarkDbError: if a required pose lies in no set (beyond ``budget``), or
            HiGHS found no feasible solution in time.
    """
    if budget is not None and budget <= 0:
        budget = None
    if required.size == 0 or not sets:
        if required.size > (budget or 0):
            raise LandmarkDbError('set cover infeasible: no candidate sets')
        return np.zeros(0, dtype=np.int64), True
    matrix = cover_matrix(n_poses, required, sets)
    empty_rows = np.diff(matrix.indptr) == 0
    if empty_rows.any():
        n_empty = int(empty_rows.sum())
        if n_empty > (budget or 0):
            bad = required[np.flatnonzero(empty_rows)[0]]
            raise LandmarkDbError(f'set cover infeasible: pose {int(bad)} lies in no candidate')
        budget = None if budget is None else budget - n_empty
        matrix = matrix[np.flatnonzero(~empty_rows)]
    # Poses lying in exactly the same candidates have identical rows: one row each.
    matrix, members = merge_identical_rows(matrix)
    matrix, columns, kept = reduce_by_dominance(matrix, rows=not budget)
    members = [members[r] for r in kept]
    n_sets, n_rows = matrix.shape[1], matrix.shape[0]
    cost = np.ones(n_sets)
    constraints = [LinearConstraint(matrix, lb=1, ub=np.inf)]
    if budget:
        row_weight = np.array([m.size for m in members], dtype=float)
        matrix = sp.hstack([matrix, sp.identity(n_rows, format='csr')]).tocsr()
        cost = np.concatenate([cost, row_weight / (row_weight.sum() + 1.0)])
        limit = sp.csr_matrix(np.concatenate([np.zeros(n_sets), row_weight])[None, :])
        constraints = [LinearConstraint(matrix, lb=1, ub=np.inf),
                       LinearConstraint(limit, lb=0, ub=float(budget))]
    options = {'disp': False}
    if time_limit is not None:
        options['time_limit'] = float(time_limit)
    if relative_gap is not None:
        options['mip_rel_gap'] = float(relative_gap)
    if node_limit is not None:
        options['node_limit'] = int(node_limit)
    start = time.perf_counter()
    result = milp(c=cost, constraints=constraints, integrality=np.ones(cost.size),
                  bounds=Bounds(0, 1), options=options)
    if time_limit is not None and result.status != 0 and \
            time.perf_counter() - start >= 0.95 * time_limit:
        _LOG.warning('set cover (%d sets x %d pose patterns) stopped by its %.3g s time '
                     'limit, not its node limit: the result depends on the speed of this '
                     'machine', n_sets, n_rows, time_limit)
    if result.x is None:
        raise LandmarkDbError(f'set cover: HiGHS found no cover ({result.message})')
    chosen = columns[np.flatnonzero(result.x[:n_sets] > 0.5)]
    return chosen, bool(result.status == 0)


def relaxed_uncovered(n_poses: int, required: np.ndarray, sets: list[np.ndarray],
                      budget: int, method: str = 'highs-ipm',
                      presolve: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Solve the LP relaxation of the budgeted partial cover.

    min sum x_j s.t. sum_{j: v in S_j} x_j + y_v >= 1, sum y_v <= budget, 0 <= x, y <= 1.
    ``y_v`` near 1 marks poses the relaxation prefers to leave uncovered.

    Args:
        n_poses: number of poses.
        required: sorted poses to cover.
        sets: sorted pose index arrays (the candidate regions).
        budget: most required poses that may stay uncovered.
        method: ``scipy.optimize.linprog`` HiGHS method.
        presolve: whether HiGHS presolves the LP.

    Returns:
        ``(len(required),)`` y values and ``(len(sets),)`` x values (all 0 when the
        LP fails).
    """
    if required.size == 0 or not sets:
        return np.ones(required.size), np.zeros(len(sets))
    matrix = cover_matrix(n_poses, required, sets)
    merged, members = merge_identical_rows(matrix)
    weight = np.array([m.size for m in members], dtype=float)
    n_sets, n_rows = len(sets), merged.shape[0]
    cover = sp.hstack([merged, sp.identity(n_rows, format='csr')]).tocsr()
    limit = sp.csr_matrix(np.concatenate([np.zeros(n_sets), weight])[None, :])
    cost = np.concatenate([np.ones(n_sets), weight * 1e-6])
    result = linprog(cost, A_ub=sp.vstack([-cover, limit]).tocsr(),
                     b_ub=np.concatenate([-np.ones(n_rows), [float(budget)]]),
                     bounds=(0, 1), method=method, options={'presolve': presolve})
    y = np.zeros(required.size)
    if result.x is None:
        return y, np.zeros(n_sets)
    for value, rows in zip(result.x[n_sets:], members):
        y[rows] = value
    return y, result.x[:n_sets]


def greedy_partial_cover(matrix: sp.csc_matrix, weight: np.ndarray, budget: float) -> np.ndarray:
    """Chvatal's greedy set cover, stopped once at most ``budget`` weight is uncovered.

    Repeatedly takes the set covering the most uncovered weight (ties: the lowest
    index); scores are updated lazily (a set's score only falls, so a popped score
    that is still exact is the maximum).

    Args:
        matrix: (rows x sets) 0/1 incidence matrix.
        weight: each row's weight (its pose count after merging identical rows).
        budget: most weight that may stay uncovered.

    Returns:
        Boolean mask of the chosen sets.
    """
    csc = sp.csc_matrix(matrix)
    covered = np.zeros(csc.shape[0], dtype=bool)
    score = np.asarray(csc.T @ weight).ravel()
    heap = [(-float(value), j) for j, value in enumerate(score) if value > 0]
    heapq.heapify(heap)
    chosen = np.zeros(csc.shape[1], dtype=bool)
    uncovered = float(weight.sum())
    while uncovered > budget and heap:
        negative, j = heapq.heappop(heap)
        rows = csc.indices[csc.indptr[j]:csc.indptr[j + 1]]
        rows = rows[~covered[rows]]
        exact = float(weight[rows].sum())
        if exact < -negative:
            if exact > 0:
                heapq.heappush(heap, (-exact, j))
            continue
        chosen[j] = True
        covered[rows] = True
        uncovered -= exact
    return chosen
