"""rho-neighbourhoods and the rho-MORDP = 0-MORDP reduction (Section 4.1).

* N_rho(v) = {u : delta(u, v) <= rho} by graph distance in G (Definition 3.6).
* Theorem 4.1 (reduction): F~_v = intersection of F_w over w in N_rho(v). Computed as
  rho successive 1-erosions of every feature's visibility set, since
  N_rho(v) = union of N_{rho-1}(u) over u in N_1(v): a pose keeps feature f in one
  erosion step iff all of N_1(v) sees f, i.e. iff ((A + I) @ V)[v, f] = |N_1(v)|.
  Each step is one sparse matrix product, never a per-pose loop.
* Theorem 4.2 (expansion): a reduced region R~ becomes R' = union of N_rho(v) over
  v in R~; R' is connected when R~ is and sees the same landmark (Lemma 4.3).
* Coverage under rho > 0 (Definition 3.7): pose v is covered iff some region
  contains all of N_rho(v); :func:`covered_poses` computes this for the validator and
  for the ``uncovered`` list, in original pose indices.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ['covered_poses', 'expand_region', 'neighbourhood_matrix', 'reduce_visibility']


def _with_self_loops(adjacency: sp.csr_matrix) -> sp.csr_matrix:
    n = adjacency.shape[0]
    matrix = (adjacency.astype(np.int32) + sp.identity(n, dtype=np.int32, format='csr')).tocsr()
    matrix.data[:] = 1
    return matrix


def neighbourhood_matrix(adjacency: sp.csr_matrix, rho: int) -> sp.csr_matrix:
    """Return the ``(n, n)`` int8 0/1 CSR matrix whose row v marks N_rho(v).

    Args:
        adjacency: ``(n, n)`` adjacency of G.
        rho: radius (>= 0).
    """
    one = _with_self_loops(adjacency)
    result = sp.identity(adjacency.shape[0], dtype=np.int32, format='csr')
    for _ in range(rho):
        result = (result @ one).tocsr()
        result.data[:] = 1
    result = result.astype(np.int8)
    result.sort_indices()
    return result


def reduce_visibility(adjacency: sp.csr_matrix, visible: sp.csr_matrix,
                      rho: int) -> sp.csr_matrix:
    """Return the reduced visibility F~_v = intersection of F_w over N_rho(v) (Thm 4.1).

    Args:
        adjacency: ``(n, n)`` adjacency of G.
        visible: ``(n, f)`` bool CSR visibility.
        rho: radius (>= 0).

    Returns:
        ``(n, f)`` bool CSR reduced visibility with sorted indices.
    """
    one = _with_self_loops(adjacency)
    degree = np.diff(one.indptr).astype(np.int32)
    current = sp.csr_matrix(visible, dtype=bool)
    for _ in range(rho):
        counts = (one @ current.astype(np.int32)).tocsr()
        counts.sort_indices()
        row_of = np.repeat(np.arange(counts.shape[0]), np.diff(counts.indptr))
        keep = counts.data == degree[row_of]
        current = sp.csr_matrix(
            (np.ones(int(keep.sum()), dtype=bool), (row_of[keep], counts.indices[keep])),
            shape=visible.shape)
    current.sort_indices()
    return current


def expand_region(neighbourhoods: sp.csr_matrix, poses: np.ndarray) -> np.ndarray:
    """Return the sorted union of N_rho(v) over ``poses`` (Theorem 4.2)."""
    if poses.size == 0:
        return poses
    rows = neighbourhoods[poses]
    return np.unique(rows.indices).astype(np.int64)


def covered_poses(neighbourhoods: sp.csr_matrix, regions: list[np.ndarray]) -> np.ndarray:
    """Return ``(n,)`` bool: poses v whose whole N_rho(v) lies inside one region.

    Args:
        neighbourhoods: N_rho rows from :func:`neighbourhood_matrix`.
        regions: sorted pose index arrays.
    """
    n = neighbourhoods.shape[0]
    covered = np.zeros(n, dtype=bool)
    inside = np.zeros(n, dtype=bool)
    sizes = np.diff(neighbourhoods.indptr)
    for poses in regions:
        if poses.size == 0:
            continue
        inside[poses] = True
        rows = neighbourhoods[poses]
        hits = np.add.reduceat(inside[rows.indices].astype(np.int64), rows.indptr[:-1]) \
            if rows.nnz else np.zeros(poses.size, dtype=np.int64)
        covered[poses[hits == sizes[poses]]] = True
        inside[poses] = False
    return covered
