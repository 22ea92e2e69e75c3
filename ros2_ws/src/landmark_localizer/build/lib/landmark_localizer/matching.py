"""Descriptor matching by BLAS: nearest neighbours, ratio test, mutual (symmetric) check.

Squared distances ``|a|^2 + |b|^2 - 2 a.b`` come from one float32 matrix product; the
candidate sets here are small (an image's features against a region's or the class
index's descriptors), so this is faster than building a FLANN index per query.
"""
from __future__ import annotations

import numpy as np

__all__ = ['grouped_nearest', 'mutual_matches', 'squared_distances']


def squared_distances(a: np.ndarray, b: np.ndarray, b_norms: np.ndarray | None = None
                      ) -> np.ndarray:
    """(n, m) squared Euclidean distances between rows of ``a`` and ``b`` (float32)."""
    a = np.asarray(a, np.float32)
    b = np.asarray(b, np.float32)
    a_norms = np.einsum('ij,ij->i', a, a)
    if b_norms is None:
        b_norms = np.einsum('ij,ij->i', b, b)
    d2 = a_norms[:, None] + b_norms[None, :] - 2.0 * (a @ b.T)
    return np.maximum(d2, 0.0, out=d2)


def grouped_nearest(d2: np.ndarray, groups: np.ndarray, n_groups: int
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Nearest and second-nearest *group* of every row (a group: a class's descriptors).

    Args:
        d2: (n, m) squared distances.
        groups: (m,) group id of each column.
        n_groups: Number of groups.

    Returns:
        ``(best_group, best_d, second_d)``: per row the nearest group, its distance and
        the distance of the nearest other group (inf when there is none).
    """
    n = d2.shape[0]
    if n == 0 or d2.shape[1] == 0:
        return (np.full(n, -1, np.int64), np.full(n, np.inf), np.full(n, np.inf))
    per_group = np.full((n, n_groups), np.inf, np.float32)
    # Minimum over each group's columns: sort the columns by group, reduceat minima.
    order = np.argsort(groups, kind='stable')
    sorted_groups = groups[order]
    starts = np.flatnonzero(np.r_[True, sorted_groups[1:] != sorted_groups[:-1]])
    minima = np.minimum.reduceat(d2[:, order], starts, axis=1)
    per_group[:, sorted_groups[starts]] = minima
    if n_groups == 1:
        best = np.zeros(n, np.int64)
        return best, np.sqrt(per_group[:, 0]), np.full(n, np.inf)
    two = np.argpartition(per_group, 1, axis=1)[:, :2]
    first = np.take_along_axis(per_group, two, axis=1)
    swap = first[:, 1] < first[:, 0]
    best = np.where(swap, two[:, 1], two[:, 0])
    best_d = np.sqrt(np.where(swap, first[:, 1], first[:, 0]))
    second_d = np.sqrt(np.where(swap, first[:, 0], first[:, 1]))
    return best.astype(np.int64), best_d, second_d


def mutual_matches(query: np.ndarray, train: np.ndarray, ratio: float,
                   max_distance: float) -> np.ndarray:
    """Pairs ``(i, j)`` where ``j`` is ``i``'s nearest train row and ``i`` is ``j``'s.

    The symmetry check of thesis 6.2.1 ("match back from the model view"): a query
    feature is kept only if its nearest neighbour also has it as nearest neighbour,
    passes Lowe's ratio test against the second nearest, and is within ``max_distance``.

    Returns:
        (p, 2) int64 index pairs.
    """
    if len(query) == 0 or len(train) == 0:
        return np.zeros((0, 2), np.int64)
    d2 = squared_distances(query, train)
    j = np.argmin(d2, axis=1)
    i = np.argmin(d2, axis=0)
    rows = np.arange(len(query))
    mutual = i[j] == rows
    best = d2[rows, j]
    if d2.shape[1] > 1:
        part = np.partition(d2, 1, axis=1)[:, 1]
        good = best < (ratio * ratio) * part
    else:
        good = np.ones(len(query), bool)
    keep = mutual & good & (best <= max_distance * max_distance)
    return np.stack([rows[keep], j[keep]], axis=1).astype(np.int64)
