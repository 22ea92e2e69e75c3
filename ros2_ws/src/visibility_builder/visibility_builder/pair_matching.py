"""Matching the features of pose pairs for Algorithm 6.3 (Section 6.2.1): relation (6.4).

For every pair of poses within ``gamma`` edges, each feature's nearest neighbour among
the other pose's features within tau, in both directions (:func:`match_pose_pair`):
mutual pairs merge classes, non-mutual ones break symmetry, two features of one pose
within tau of each other break local uniqueness. Distances are one augmented BLAS
product per block of pose pairs (``|a|^2 - 2 a.b + |b|^2`` from uint8 descriptors as
float32, exact for SIFT's integer descriptors), the column argmin without a second
product; :func:`match_chunk` does a chunk of pose pairs, in the calling process or in a
spawn pool's workers (:func:`match_chunk_in_worker`). :mod:`.classes` composes the
chunks into classes.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from vbn_common.allocator import reuse_freed_memory
from vbn_common.blas import set_blas_threads

__all__ = ['PairMatches', 'chunk_by_first_pose', 'chunk_descriptors', 'init_worker',
           'match_chunk', 'match_chunk_in_worker', 'match_pose_pair']


# Most distance-matrix entries per BLAS product (4 MB: small products stay in cache).
_BLOCK_ENTRIES = 1_000_000


# Work chunks per worker process (balances the end of the pool's queue).
_CHUNKS_PER_WORKER = 8


@dataclass
class PairMatches:
    """Nearest-neighbour relations between the features of two poses a and b.

    Attributes:
        mutual: ``(k, 2)`` int64 feature index pairs (in a, in b) that are each
            other's nearest neighbour within tau: their classes merge.
        broken_a: ``(p,)`` indices of a's features that are in a non-symmetric
            nearest-neighbour relation within tau (or fail the ratio test).
        broken_b: ``(q,)`` the same for b's features.
        tested: nearest-neighbour queries made (``n_a + n_b``).
        within_tau: queries whose nearest neighbour lies within tau.
    """

    mutual: np.ndarray
    broken_a: np.ndarray
    broken_b: np.ndarray
    tested: int
    within_tau: int


def match_pose_pair(a: np.ndarray, b: np.ndarray, tau: float, ratio: float | None = None,
                    symmetry_factor: float = 1.0) -> PairMatches:
    """Evaluate relation (6.4) in both directions between two poses' features.

    Args:
        a: ``(n_a, d)`` descriptors of pose a (float32 or uint8).
        b: ``(n_b, d)`` descriptors of pose b.
        tau: largest matching distance.
        ratio: optional Lowe ratio (see :class:`ClassConfig`).
        symmetry_factor: non-mutual nearest neighbours within this times ``tau``
            break symmetry (see :class:`ClassConfig`).

    Returns:
        The :class:`PairMatches` of the pair.
    """
    d2 = _augmented(a)[0] @ _augmented(b)[1].T
    return _relations(d2, float(tau) ** 2, ratio, (float(symmetry_factor) * tau) ** 2)


def _relations(d2: np.ndarray, tau2: float, ratio: float | None,
               check2: float | None = None) -> PairMatches:
    """Relation (6.4) both ways from the squared distances of one pose pair.

    ``check2`` (>= ``tau2``; default ``tau2``) is the squared radius within which a
    nearest neighbour that is not mutual breaks symmetry.
    """
    check2 = tau2 if check2 is None else max(check2, tau2)
    n_a, n_b = d2.shape
    rows = np.arange(n_a)
    cols = np.arange(n_b)
    fwd = d2.argmin(axis=1)   # nearest neighbour in b of each feature of a
    bwd = _argmin_columns(d2)  # nearest neighbour in a of each feature of b
    fwd_d2 = d2[rows, fwd]
    bwd_d2 = d2[bwd, cols]
    near_a = fwd_d2 <= tau2
    near_b = bwd_d2 <= tau2
    mutual_a = bwd[fwd] == rows
    mutual_b = fwd[bwd] == cols
    ok_a = near_a & mutual_a
    ok_b = near_b & mutual_b
    if ratio is not None:
        ok_a &= _passes_ratio(d2, fwd_d2, near_a, ratio, axis=1)
        ok_b &= _passes_ratio(d2, bwd_d2, near_b, ratio, axis=0)
    # A mutual pair within tau is found from both sides; it merges only when both
    # sides accept it (always, without the ratio test).
    merge_a = ok_a & ok_b[fwd]
    merge_b = ok_b & ok_a[bwd]
    i = np.flatnonzero(merge_a)
    mutual = np.column_stack([i, fwd[i]]).astype(np.int64)
    # A non-mutual nearest neighbour within the check radius, or a match within tau
    # that a side rejected, breaks the relation for both ends.
    bad_a = np.flatnonzero(((fwd_d2 <= check2) & ~mutual_a) | (near_a & ~merge_a))
    bad_b = np.flatnonzero(((bwd_d2 <= check2) & ~mutual_b) | (near_b & ~merge_b))
    broken_a = np.unique(np.concatenate([bad_a, bwd[bad_b]])).astype(np.int64)
    broken_b = np.unique(np.concatenate([bad_b, fwd[bad_a]])).astype(np.int64)
    return PairMatches(mutual, broken_a, broken_b, int(n_a + n_b),
                       int(near_a.sum() + near_b.sum()))


def _argmin_columns(d2: np.ndarray) -> np.ndarray:
    """``d2.argmin(axis=0)`` (first row on ties), by a column minimum and one scan.

    numpy's ``argmin`` along the rows of a C-ordered matrix is several times slower
    than ``min`` along them.
    """
    hits = np.flatnonzero(d2 == d2.min(axis=0))
    rows, cols = np.divmod(hits, d2.shape[1])
    _, first = np.unique(cols, return_index=True)   # first hit of each column: lowest row
    return rows[first]


def _passes_ratio(d2: np.ndarray, best_d2: np.ndarray, near: np.ndarray, ratio: float,
                  axis: int) -> np.ndarray:
    """Lowe's test ``d1 < ratio * d2`` for the queries that are ``near``."""
    passes = np.ones(best_d2.shape, dtype=bool)
    idx = np.flatnonzero(near)
    if idx.size == 0 or d2.shape[axis] < 2:
        return passes
    sub = d2[idx, :] if axis == 1 else d2[:, idx].T
    second = np.partition(sub, 1, axis=1)[:, 1]
    passes[idx] = best_d2[idx] < (ratio * ratio) * np.maximum(second, 0.0)
    return passes


def _repeated_in_pose(a: np.ndarray, tau2: float) -> np.ndarray:
    """Features of one pose whose nearest *other* feature of that pose is within tau.

    This is the pair v = w of Figure 6.3's loop (delta(v, v) = 0 <= gamma) with a
    feature never its own neighbour: the related pair either merges (breaking local
    uniqueness) or is not mutual (breaking symmetry), so both features are excluded.
    """
    left, right = _augmented(a)
    return _repeated_from_augmented(left, right, tau2)


def _repeated_from_augmented(left: np.ndarray, right: np.ndarray, tau2: float) -> np.ndarray:
    """:func:`_repeated_in_pose` from the pose's two augmented forms."""
    d2 = left @ right.T
    np.fill_diagonal(d2, np.inf)
    nearest = d2.argmin(axis=1)
    close = np.flatnonzero(d2[np.arange(len(left)), nearest] <= tau2)
    return np.unique(np.concatenate([close, nearest[close]])).astype(np.int64)


def _augmented(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows ``[a, |a|^2, 1]`` and ``[-2 a, 1, |a|^2]`` (float32) of one pose's features.

    The product of the first form of pose v with the second of pose w is the matrix of
    squared distances ``|a|^2 + |b|^2 - 2 a.b`` in one BLAS call (exact for integer
    descriptors: every term and partial sum is an integer below 2**24).
    """
    a = np.asarray(a, dtype=np.float32)
    n, d = a.shape
    sq = np.einsum('ij,ij->i', a, a)
    left = np.empty((n, d + 2), np.float32)
    left[:, :d] = a
    left[:, d] = sq
    left[:, d + 1] = 1.0
    right = np.empty((n, d + 2), np.float32)
    np.multiply(a, -2.0, out=right[:, :d])
    right[:, d] = 1.0
    right[:, d + 1] = sq
    return left, right


def chunk_by_first_pose(pairs: np.ndarray, self_poses: np.ndarray, workers: int
                         ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split the work into chunks: runs of pairs sharing the first pose, plus self checks.

    Returns:
        ``(pairs, self_poses)`` per chunk; each pose of ``self_poses`` (compared with
        itself, ``same_pose``) goes to the chunk whose first poses bracket it.
    """
    self_poses = np.asarray(self_poses, dtype=np.int64)
    if len(pairs) == 0:
        return [(pairs, self_poses)] if len(self_poses) else []
    starts = np.flatnonzero(np.r_[True, pairs[1:, 0] != pairs[:-1, 0]])
    runs = np.split(pairs, starts[1:])
    n_chunks = max(1, min(len(runs), _CHUNKS_PER_WORKER * workers if workers > 1 else 1))
    bounds = np.linspace(0, len(runs), n_chunks + 1).round().astype(int)
    chunk_pairs = [np.concatenate(runs[s:e]) for s, e in zip(bounds[:-1], bounds[1:])
                   if e > s]
    first = np.array([c[0, 0] for c in chunk_pairs], dtype=np.int64)
    owner = np.maximum(np.searchsorted(first, self_poses, side='right') - 1, 0)
    return [(c, self_poses[owner == i]) for i, c in enumerate(chunk_pairs)]


def chunk_descriptors(descriptors: list[np.ndarray], pairs: np.ndarray,
                       self_poses: np.ndarray) -> dict[int, np.ndarray]:
    """Return the descriptor arrays a chunk needs, by pose (what a worker task gets)."""
    poses = np.unique(np.concatenate([pairs.ravel(), self_poses]))
    return {int(v): descriptors[v] for v in poses}


def match_chunk(descriptors: Mapping[int, np.ndarray] | Sequence[np.ndarray],
                 offsets: np.ndarray, pairs: np.ndarray, self_poses: np.ndarray,
                 tau2: float, ratio: float | None, check2: float
                 ) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Match every pose pair of a chunk and its self poses; return global feature ids.

    Args:
        descriptors: by pose index, the descriptors (``uint8`` or float32) of at least
            the poses of ``pairs`` and ``self_poses``.
        offsets: ``(n_poses + 1,)`` first global feature id of each pose.
        pairs: ``(p, 2)`` pose pairs ``v < w``, sorted by ``v``.
        self_poses: poses whose features are compared with each other (``same_pose``).
        tau2: squared tau.
        ratio: optional Lowe ratio.
        check2: squared radius of the symmetry check.

    Returns:
        ``(mutual (k, 2), broken (p,), tested, within_tau)`` with feature ids global
        over all poses (pose offsets added).
    """
    counts = np.diff(offsets)
    # Float32 augmented forms of the poses in use; pairs are sorted by their first pose,
    # so a pose below the current first pose is never needed again and is dropped.
    forms: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def form(v: int) -> tuple[np.ndarray, np.ndarray]:
        if v not in forms:
            forms[v] = _augmented(descriptors[v])
        return forms[v]

    mutual: list[np.ndarray] = []
    broken: list[np.ndarray] = []
    tested = within = 0
    for v in np.asarray(self_poses, dtype=np.int64).tolist():
        left, right = _augmented(descriptors[v])
        broken.append(_repeated_from_augmented(left, right, tau2) + offsets[v])
    starts = np.flatnonzero(np.r_[True, pairs[1:, 0] != pairs[:-1, 0]]) if len(pairs) \
        else np.zeros(0, np.int64)
    for run in np.split(pairs, starts[1:]) if len(pairs) else []:
        v = int(run[0, 0])
        for stale in [u for u in forms if u < v]:
            del forms[stale]
        a = form(v)[0]
        partners = run[:, 1]
        # Stack the partners of v into products of at most _BLOCK_ENTRIES entries.
        sizes = counts[partners]
        budget = max(1, _BLOCK_ENTRIES // max(len(a), 1))
        group: list[int] = []
        total = 0
        groups: list[list[int]] = []
        for w, size in zip(partners.tolist(), sizes.tolist()):
            if group and total + size > budget:
                groups.append(group)
                group, total = [], 0
            group.append(w)
            total += size
        if group:
            groups.append(group)
        for group in groups:
            b = np.concatenate([form(w)[1] for w in group]) if len(group) > 1 \
                else form(group[0])[1]
            d2 = a @ b.T
            col = 0
            for w in group:
                n_w = int(counts[w])
                rel = _relations(d2[:, col:col + n_w], tau2, ratio, check2)
                col += n_w
                mutual.append(rel.mutual + np.array([offsets[v], offsets[w]]))
                broken.append(rel.broken_a + offsets[v])
                broken.append(rel.broken_b + offsets[w])
                tested += rel.tested
                within += rel.within_tau
    empty = np.zeros(0, dtype=np.int64)
    return (np.concatenate(mutual) if mutual else np.zeros((0, 2), dtype=np.int64),
            np.concatenate(broken) if broken else empty, tested, within)


def init_worker() -> None:
    set_blas_threads(1)
    reuse_freed_memory()


def match_chunk_in_worker(
        args: tuple[dict[int, np.ndarray], np.ndarray, np.ndarray, np.ndarray, float,
                    float | None, float]
) -> tuple[np.ndarray, np.ndarray, int, int]:
    return match_chunk(*args)
