"""Correspondence classes of image features: Algorithm 6.3 (Section 6.2.1, Figure 6.3).

Problem. Given the image features seen from every sampled pose, group them into
classes, one per scene feature, and drop every feature that could be confused with
another class. With a descriptor distance delta and a threshold tau, the relation

    f =_F g  <=>  delta(f, g) <= tau  and  g = argmin_{phi in F_w} delta(f, phi)   (6.4)

(g seen from pose w) is a nearest-neighbour relation, neither symmetric nor
transitive. Algorithm 6.3 restricts it to the largest set of features on which it is
an equivalence:

* it is evaluated only between poses v, w at most ``gamma`` edges apart in the pose
  graph G (the thesis's relaxation: gamma = 1 tracks features between adjacent poses,
  a gamma as large as the widest visibility region is exact);
* a mutual nearest-neighbour pair within tau merges the two features' classes
  (transitive closure);
* a nearest neighbour within tau that is not mutual breaks symmetry: the classes of
  both features are excluded, and stay excluded through later merges;
* after the closure, a class holding two features of one pose breaks local uniqueness
  (6.3) and is excluded.

With ``exclusion='feature'`` (the default, a departure listed below) a broken
relation excludes its two features instead of their whole classes.

Every feature starts in a class of its own, so a feature that matched nothing is a
class seen from one pose (the filters of Section 6.2.2 drop such classes).

Implementation. The outcome of Figure 6.3 does not depend on the order in which pose
pairs and features are visited (merging only grows classes and exclusion is sticky),
so the loops become array operations: for every unordered pair of poses within gamma
the squared distances ``|a|^2 + |b|^2 - 2 a.b`` come from one float32 BLAS product of
the augmented rows ``[a, |a|^2, 1]`` and ``[-2 b, 1, |b|^2]`` (a pose's partners are
stacked into products of at most 1e6 entries), nearest neighbours in both directions
are an ``argmin`` along the rows and a column minimum, and the transitive closure is
the connected components of the graph of mutual matches
(:func:`scipy.sparse.csgraph.connected_components`). SIFT descriptors are integers in
0..255 (``uint8``, kept so in memory and converted one pose at a time) with a norm of
about 512, so every product, norm and partial sum stays an integer far below 2**24 and
the float32 distances are exact: the result does not depend on the order of the
arithmetic. With ``workers > 1`` the
pose pairs are matched in a 'spawn' process pool (never forked: the builder node calls
this from a thread while rclpy runs), each task receiving only the descriptors of the
poses it compares. Complexity: O(sum over pairs of n_v n_w d) for the distances, O(N)
for the rest.

Departures from the text, with reasons:

* **Feature exclusion** (``exclusion='feature'``, the default; ``'class'`` is Figure
  6.3). Figure 6.3 excludes every member of a class in which one feature takes part
  in a non-symmetric relation. The widely visible classes that the decomposition
  needs have the most links, so one ambiguous view anywhere (the feature missed at
  one pose and its nearest neighbour there some other feature) removes exactly the
  classes worth keeping: on the room bag (3 SIFT octave layers) 501 classes reach 16
  poses with class exclusion (tau 120), 704 with feature exclusion (tau 150). Here the
  features of a broken relation are excluded before the closure (they merge with
  nothing, so no chain runs through them) and the rest of their classes stays, which
  is the thesis's own aim ("discard all the features that are not distinctive
  enough").
  Local uniqueness still excludes whole classes. Descriptors alone then leave more
  mixed classes (2.5 % instead of 0.5-0.9 % on the room bag); the builder's
  geometric verification (:mod:`visibility_builder.verification`) removes them
  (0.24 %; 0.20 % with the default 5 octave layers, ``docs/classes.md``). Splitting a
  class at its broken relations (excluding the class only when a broken relation
  joins two of its own members) and excluding a class only when two or more of its
  members are broken were measured too and kept fewer classes.
* **Pose pairs** v != w are unordered and each is compared once; the nearest
  neighbours of both directions (v -> w and w -> v) come from the same distance
  matrix, which is what the algorithm's loop over ordered pairs computes.
* **Several images per pose** (four pinhole headings, say) are given as one
  concatenated feature set per pose, as the thesis asks ("integrated into a unique
  panorama").
* **Two radii** (``symmetry_factor``, 1 by default): pairs merge within tau, but a
  nearest neighbour that is not mutual already breaks symmetry within
  ``symmetry_factor * tau``. Figure 6.3 uses tau for both; a feature whose nearest
  neighbour is not mutual but slightly beyond tau is just as ambiguous, and on the
  room bag with class exclusion and no geometric verification this is what brings
  the impure classes to 0.5 % (``docs/classes.md``). ``symmetry_factor=1`` is the
  algorithm as printed; with feature exclusion a wider radius only removes features.
* **The pair v = w** (delta(v, v) = 0 <= gamma) is compared with a feature never its
  own nearest neighbour (``same_pose``, on by default). Read literally, every feature
  is its own nearest neighbour there and the pair teaches nothing; read this way, two
  features of one image closer than tau (a repeated pattern: tiles, bricks) either
  merge, breaking local uniqueness, or are not mutual, breaking symmetry, so both are
  excluded, as the text after (6.3) wants for repeated scene features. This
  comparison uses tau itself.
* **Optional transitivity check** (``transitivity``, off by default): the closure
  chains f ~ g ~ h although f and h may be far apart; the thesis says gamma bounds
  how far "violations to the symmetry and transitivity properties" are checked but
  Figure 6.3 only checks symmetry and uniqueness. With a distance set, a class is
  excluded when two members seen from poses within gamma are farther apart than it.
* **Optional ratio test** (``ratio``, Lowe 2004): a nearest neighbour within tau whose
  distance is not below ``ratio`` times the second-nearest distance in the same image
  set is ambiguous and is treated like a non-symmetric match (both classes are
  excluded), in the spirit of the thesis's "discard all the features that are not
  distinctive enough". Off by default (see
  ``docs/classes.md`` for the measurements behind the defaults).

Reference: thesis Section 6.2.1, equations (6.3) and (6.4), Figure 6.3.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
import logging
import math
import multiprocessing
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from vbn_common.allocator import reuse_freed_memory
from vbn_common.blas import set_blas_threads, single_threaded_blas
from visibility_builder.errors import VisibilityBuilderError

__all__ = [
    'EXCLUSIONS',
    'ClassConfig',
    'ClassResult',
    'PairMatches',
    'correspondence_classes',
    'match_pose_pair',
    'pose_pairs_within',
]

logger = logging.getLogger(__name__)

# What a broken relation excludes (ClassConfig.exclusion).
EXCLUSIONS = ('feature', 'class')

# Most distance-matrix entries per BLAS product (4 MB: small products stay in cache).
_BLOCK_ENTRIES = 1_000_000
# Work chunks per worker process (balances the end of the pool's queue).
_CHUNKS_PER_WORKER = 8
# Less matching work than this many distance entries (about 10 s of one core) runs in
# the calling process: starting a spawn pool costs 1-4 s (the room bag has 0.6e9).
_MIN_POOL_ENTRIES = 2_000_000_000


@dataclass(frozen=True)
class ClassConfig:
    """Parameters of Algorithm 6.3.

    Attributes:
        tau: largest descriptor distance of a match (Euclidean; OpenCV SIFT
            descriptors have a norm of about 512).
        gamma: pose pairs at most this many edges apart in G are compared (>= 1).
        ratio: Lowe's ratio; a nearest neighbour within ``tau`` that is not closer
            than ``ratio`` times the second nearest counts as a non-symmetric match.
            ``None`` disables the test.
        workers: processes that compute the pose-pair matches (1: in this process;
            a 'spawn' pool otherwise, used when the pose pairs hold at least 2e9
            distance entries, about 10 s of one core).
        symmetry_factor: a nearest neighbour that is not mutual breaks symmetry when
            it lies within ``symmetry_factor * tau`` (1: Figure 6.3 as printed, where
            the same ``tau`` decides both merging and exclusion).
        same_pose: also compare each pose with itself, a feature never being its own
            neighbour: a feature with another feature of its own pose within ``tau``
            (a repeated pattern in one image) excludes both classes.
        transitivity: if set, a class is also excluded when two of its features, seen
            from poses at most ``gamma`` apart, are farther apart than this distance
            (the closure chained them through intermediate poses). ``None``: off.
        exclusion: what a broken relation excludes: ``'feature'`` its two features
            (they merge with nothing, their classes stay), ``'class'`` the whole
            classes of both (Figure 6.3 as printed).
    """

    tau: float = 150.0
    gamma: int = 2
    ratio: float | None = None
    workers: int = 1
    same_pose: bool = True
    symmetry_factor: float = 1.0
    transitivity: float | None = None
    exclusion: str = 'feature'

    def __post_init__(self) -> None:
        if not (isinstance(self.tau, (int, float)) and math.isfinite(self.tau)
                and self.tau > 0):
            raise VisibilityBuilderError(f'tau must be a positive number, got {self.tau!r}')
        if isinstance(self.gamma, bool) or not isinstance(self.gamma, (int, np.integer)) \
                or self.gamma < 1:
            raise VisibilityBuilderError(f'gamma must be an integer >= 1, got {self.gamma!r}')
        if self.ratio is not None and not (isinstance(self.ratio, (int, float))
                                           and 0 < self.ratio <= 1):
            raise VisibilityBuilderError(f'ratio must be in (0, 1] or None, got {self.ratio!r}')
        if isinstance(self.workers, bool) or not isinstance(self.workers, (int, np.integer)) \
                or self.workers < 1:
            raise VisibilityBuilderError(f'workers must be an integer >= 1, got {self.workers!r}')
        if not (isinstance(self.symmetry_factor, (int, float))
                and math.isfinite(self.symmetry_factor) and self.symmetry_factor >= 1):
            raise VisibilityBuilderError(
                f'symmetry_factor must be a number >= 1, got {self.symmetry_factor!r}')
        if self.exclusion not in EXCLUSIONS:
            raise VisibilityBuilderError(
                f'exclusion must be one of {", ".join(EXCLUSIONS)}, got {self.exclusion!r}')
        if self.transitivity is not None and not (
                isinstance(self.transitivity, (int, float)) and self.transitivity > 0):
            raise VisibilityBuilderError(
                f'transitivity must be a positive distance or None, got {self.transitivity!r}')


@dataclass
class ClassResult:
    """Feature classes of Algorithm 6.3.

    Attributes:
        labels: per pose, ``(n_i,)`` int64 class id of each feature (the rows of that
            pose's descriptor array), -1 for an excluded feature.
        n_classes: number of classes kept; ids are ``0 .. n_classes - 1``.
        visibility: ``(n_poses, n_classes)`` bool CSR; ``visibility[v, c]`` is true when
            pose v sees a feature of class c (the thesis's F_v).
        stats: counts of the run (see :func:`correspondence_classes`).
    """

    labels: list[np.ndarray]
    n_classes: int
    visibility: sp.csr_matrix
    stats: dict[str, float] = field(default_factory=dict)


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


def pose_pairs_within(edges: np.ndarray, n_poses: int, gamma: int) -> np.ndarray:
    """Unordered pose pairs at most ``gamma`` edges apart in the pose graph.

    Args:
        edges: ``(m, 2)`` int pose index pairs (undirected; self-loops ignored).
        n_poses: number of poses.
        gamma: largest graph distance (>= 1).

    Returns:
        ``(p, 2)`` int64 pairs ``(v, w)`` with ``v < w``, sorted.

    Raises:
        VisibilityBuilderError: on an edge index outside ``0 .. n_poses - 1``.
    """
    edges = _check_edges(edges, n_poses)
    if n_poses == 0 or len(edges) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    keep = edges[:, 0] != edges[:, 1]
    rows = np.concatenate([edges[keep, 0], edges[keep, 1]])
    cols = np.concatenate([edges[keep, 1], edges[keep, 0]])
    adjacency = sp.csr_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)),
                              shape=(n_poses, n_poses))
    adjacency.data[:] = 1
    # Breadth-first growth of all neighbourhoods at once: reach_{k+1} = reach_k (I + A).
    step = (adjacency + sp.identity(n_poses, dtype=np.int8, format='csr')).astype(bool)
    reach = sp.identity(n_poses, dtype=bool, format='csr')
    for _ in range(int(gamma)):
        grown = (reach @ step).astype(bool)
        if grown.nnz == reach.nnz:
            break
        reach = grown
    reach = sp.triu(reach, k=1).tocoo()
    pairs = np.column_stack([reach.row, reach.col]).astype(np.int64)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order]


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


def correspondence_classes(pose_descriptors: Sequence[np.ndarray], edges: np.ndarray,
                           config: ClassConfig | None = None) -> ClassResult:
    """Compute feature classes and per-pose visibility with Algorithm 6.3.

    Args:
        pose_descriptors: per sampled pose, ``(n_i, d)`` descriptors of all features
            of that pose (all its images concatenated); ``n_i`` may be 0. ``uint8``
            arrays (SIFT) stay ``uint8`` in memory; other dtypes are converted to float32.
        edges: ``(m, 2)`` int pose graph G (undirected).
        config: tau, gamma, ratio and workers; defaults of :class:`ClassConfig`.

    Returns:
        The :class:`ClassResult`. ``stats`` holds: ``poses``, ``features``,
        ``pose_pairs`` (compared), ``nn_tested`` (nearest-neighbour queries),
        ``nn_within_tau``, ``mutual`` (mutual matches merged), ``broken_features``
        (features in a non-symmetric relation), ``classes_before`` (classes after the
        closure, singletons included), ``excluded_symmetry``,
        ``excluded_uniqueness`` (classes excluded by each rule; a class breaking both
        counts under symmetry), ``classes``, ``multi_pose_classes`` (kept classes seen
        from at least two poses), ``features_kept``, ``seconds``.

    Raises:
        VisibilityBuilderError: on descriptor arrays of the wrong shape or
            dimension, non-finite values, or edges outside the pose range.

    Example:
        >>> a = np.eye(2, 4, dtype=np.float32) * 100
        >>> result = correspondence_classes([a, a + 1], [[0, 1]], ClassConfig(tau=10))
        >>> result.n_classes, [lab.tolist() for lab in result.labels]
        (2, [[0, 1], [0, 1]])
    """
    config = config if config is not None else ClassConfig()
    start = time.perf_counter()
    descriptors = _check_descriptors(pose_descriptors)
    n_poses = len(descriptors)
    counts = np.array([len(d) for d in descriptors], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n_features = int(offsets[-1])
    pairs = pose_pairs_within(edges, n_poses, config.gamma)
    pairs = pairs[(counts[pairs[:, 0]] > 0) & (counts[pairs[:, 1]] > 0)]

    self_poses = np.flatnonzero(counts > 1) if config.same_pose else np.zeros(0, np.int64)
    entries = int(np.sum(counts[pairs[:, 0]] * counts[pairs[:, 1]]))
    use_pool = config.workers > 1 and entries >= _MIN_POOL_ENTRIES
    chunks = _chunk_by_first_pose(pairs, self_poses, config.workers if use_pool else 1)
    tau2 = float(config.tau) ** 2
    check2 = (float(config.symmetry_factor) * float(config.tau)) ** 2
    with single_threaded_blas():
        if use_pool and len(chunks) > 1:
            # spawn, not fork: the builder node runs this with rclpy's threads alive.
            context = multiprocessing.get_context('spawn')
            with ProcessPoolExecutor(max_workers=config.workers, mp_context=context,
                                     initializer=_init_worker) as pool:
                results = list(pool.map(
                    _match_chunk_in_worker,
                    [(_chunk_descriptors(descriptors, chunk_pairs, chunk_self), offsets,
                      chunk_pairs, chunk_self, tau2, config.ratio, check2)
                     for chunk_pairs, chunk_self in chunks]))
        else:
            results = [_match_chunk(descriptors, offsets, chunk_pairs, chunk_self, tau2,
                                    config.ratio, check2)
                       for chunk_pairs, chunk_self in chunks]

    mutual = [r[0] for r in results]
    broken = [r[1] for r in results]
    merged = np.concatenate(mutual) if mutual else np.zeros((0, 2), dtype=np.int64)
    broken_ids = np.unique(np.concatenate(broken)) if broken else np.zeros(0, dtype=np.int64)
    if config.exclusion == 'feature':
        # The features of a broken relation merge with nothing: no chain runs through them.
        is_broken = np.zeros(n_features, dtype=bool)
        is_broken[broken_ids] = True
        merged = merged[~(is_broken[merged[:, 0]] | is_broken[merged[:, 1]])]
    tested = sum(r[2] for r in results)
    within = sum(r[3] for r in results)

    # Transitive closure: classes are the connected components of the mutual matches.
    graph = sp.coo_matrix((np.ones(len(merged), dtype=np.int8), (merged[:, 0], merged[:, 1])),
                          shape=(n_features, n_features))
    n_components, component = connected_components(graph, directed=False)
    pose_of = np.repeat(np.arange(n_poses, dtype=np.int64), counts)

    # Symmetry: a class holding a feature of a broken relation is excluded (with
    # feature exclusion such a feature is a class of its own).
    excluded_sym = np.zeros(n_components, dtype=bool)
    excluded_sym[component[broken_ids]] = True
    # Local uniqueness (6.3): a class with two features of one pose is excluded.
    key = component.astype(np.int64) * max(n_poses, 1) + pose_of
    key_sorted = np.sort(key)
    repeated = key_sorted[1:][key_sorted[1:] == key_sorted[:-1]] // max(n_poses, 1)
    excluded_unique = np.zeros(n_components, dtype=bool)
    excluded_unique[repeated] = True
    excluded_unique &= ~excluded_sym
    # Transitivity within gamma: the closure may chain f ~ g ~ h while f and h, seen
    # from poses gamma or fewer apart, are farther than tau from each other.
    excluded_trans = np.zeros(n_components, dtype=bool)
    if config.transitivity is not None and len(pairs):
        sizes = np.bincount(component, minlength=n_components)
        candidates = (sizes > 1) & ~(excluded_sym | excluded_unique)
        excluded_trans = _breaks_transitivity(component, pose_of, descriptors, offsets,
                                              pairs, n_components,
                                              float(config.transitivity) ** 2, candidates)
    keep = ~(excluded_sym | excluded_unique | excluded_trans)

    new_id = np.full(n_components, -1, dtype=np.int64)
    n_classes = int(keep.sum())
    new_id[keep] = np.arange(n_classes)
    flat_labels = new_id[component]
    kept = flat_labels >= 0
    visibility = sp.csr_matrix(
        (np.ones(int(kept.sum()), dtype=bool), (pose_of[kept], flat_labels[kept])),
        shape=(n_poses, n_classes))
    visibility.sort_indices()
    labels = [flat_labels[offsets[i]:offsets[i + 1]].copy() for i in range(n_poses)]
    poses_per_class = np.bincount(flat_labels[kept], minlength=n_classes)
    seconds = time.perf_counter() - start
    stats: dict[str, float] = {
        'poses': n_poses,
        'features': n_features,
        'pose_pairs': len(pairs),
        'nn_tested': int(tested),
        'nn_within_tau': int(within),
        'mutual': len(merged),
        'broken_features': len(broken_ids),
        'classes_before': int(n_components),
        'excluded_symmetry': int(excluded_sym.sum()),
        'excluded_uniqueness': int(excluded_unique.sum()),
        'excluded_transitivity': int(excluded_trans.sum()),
        'classes': n_classes,
        'multi_pose_classes': int(np.sum(poses_per_class >= 2)),
        'features_kept': int(kept.sum()),
        'seconds': round(seconds, 3),
    }
    logger.info('correspondence classes (tau=%g, gamma=%d, ratio=%s): %s', config.tau,
                config.gamma, config.ratio, stats)
    return ClassResult(labels, n_classes, visibility, stats)


def _breaks_transitivity(component: np.ndarray, pose_of: np.ndarray,
                         descriptors: list[np.ndarray], offsets: np.ndarray,
                         pairs: np.ndarray, n_components: int, tau2: float,
                         candidates: np.ndarray) -> np.ndarray:
    """Components with two members, at poses within gamma, farther apart than tau.

    Only components in ``candidates`` (bool per component: several members and one
    per pose) are checked. For every compared pose pair (v, w) and every such class
    seen from both, the two members' descriptor distance is computed directly.
    """
    n_poses = len(descriptors)
    member = candidates[component]
    feat = np.flatnonzero(member)
    broken = np.zeros(n_components, dtype=bool)
    if feat.size == 0:
        return broken
    # pose x component incidence of the candidate members, holding feature id + 1
    incidence = sp.csr_matrix(
        (feat + 1, (pose_of[feat], component[feat])), shape=(n_poses, n_components))
    step = max(1, 4_000_000 // max(int(incidence.getnnz(axis=1).max()), 1))
    for lo in range(0, len(pairs), step):
        chunk = pairs[lo:lo + step]
        left = incidence[chunk[:, 0]]
        right = incidence[chunk[:, 1]]
        both = left.astype(bool).multiply(right.astype(bool)).tocoo()
        if both.nnz == 0:
            continue
        f = np.asarray(left[both.row, both.col]).ravel() - 1
        h = np.asarray(right[both.row, both.col]).ravel() - 1
        a = _gather(descriptors, offsets, f)
        b = _gather(descriptors, offsets, h)
        diff = a - b
        far = np.einsum('ij,ij->i', diff, diff) > tau2
        broken[both.col[far]] = True
    return broken


def _gather(descriptors: list[np.ndarray], offsets: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """Rows of the concatenated descriptors by global feature id."""
    pose = np.searchsorted(offsets, ids, side='right') - 1
    out = np.empty((len(ids), descriptors[0].shape[1] if len(ids) else 0), np.float32)
    for v in np.unique(pose):
        sel = pose == v
        out[sel] = descriptors[v][ids[sel] - offsets[v]]
    return out


# -- matching kernels ------------------------------------------------------------------

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


def _chunk_by_first_pose(pairs: np.ndarray, self_poses: np.ndarray, workers: int
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


def _chunk_descriptors(descriptors: list[np.ndarray], pairs: np.ndarray,
                       self_poses: np.ndarray) -> dict[int, np.ndarray]:
    """Return the descriptor arrays a chunk needs, by pose (what a worker task gets)."""
    poses = np.unique(np.concatenate([pairs.ravel(), self_poses]))
    return {int(v): descriptors[v] for v in poses}


def _match_chunk(descriptors: Mapping[int, np.ndarray] | Sequence[np.ndarray],
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


def _init_worker() -> None:
    set_blas_threads(1)
    reuse_freed_memory()


def _match_chunk_in_worker(
        args: tuple[dict[int, np.ndarray], np.ndarray, np.ndarray, np.ndarray, float,
                    float | None, float]
) -> tuple[np.ndarray, np.ndarray, int, int]:
    return _match_chunk(*args)


# -- input checks ----------------------------------------------------------------------

def _check_descriptors(pose_descriptors: Sequence[np.ndarray]) -> list[np.ndarray]:
    out: list[np.ndarray] = []
    dim: int | None = None
    for i, d in enumerate(pose_descriptors):
        arr = np.asarray(d)
        if arr.ndim != 2:
            raise VisibilityBuilderError(
                f'descriptors of pose {i} must be a 2-D (n, d) array, got shape {arr.shape}')
        if arr.shape[0] > 0:
            if dim is None:
                dim = arr.shape[1]
            elif arr.shape[1] != dim:
                raise VisibilityBuilderError(
                    f'descriptors of pose {i} have dimension {arr.shape[1]}, expected {dim}')
        if arr.dtype == np.uint8:
            out.append(np.ascontiguousarray(arr))
            continue
        arr = np.ascontiguousarray(arr, dtype=np.float32)
        if not np.isfinite(arr).all():
            raise VisibilityBuilderError(f'descriptors of pose {i} contain NaN or inf')
        out.append(arr)
    return out


def _check_edges(edges: np.ndarray, n_poses: int) -> np.ndarray:
    arr = np.asarray(edges)
    if arr.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise VisibilityBuilderError(f'edges must be an (m, 2) array, got shape {arr.shape}')
    if not np.issubdtype(arr.dtype, np.integer):
        raise VisibilityBuilderError(f'edges must be integer pose indices, got {arr.dtype}')
    if arr.min() < 0 or arr.max() >= n_poses:
        bad = int(arr.max() if arr.max() >= n_poses else arr.min())
        raise VisibilityBuilderError(
            f'edge pose index {bad} is outside 0 .. {n_poses - 1}')
    return arr.astype(np.int64)
