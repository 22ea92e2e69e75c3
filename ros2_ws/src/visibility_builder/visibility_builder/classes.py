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

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import logging
import math
import time

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from vbn_common.blas import single_threaded_blas
from vbn_common.workers import map_in_processes
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.pair_matching import (
    chunk_by_first_pose,
    chunk_descriptors,
    init_worker,
    match_chunk,
    match_chunk_in_worker,
)

__all__ = [
    'EXCLUSIONS',
    'ClassConfig',
    'ClassResult',
    'correspondence_classes',
    'pose_pairs_within',
]

logger = logging.getLogger(__name__)

# What a broken relation excludes (ClassConfig.exclusion).
EXCLUSIONS = ('feature', 'class')





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




def correspondence_classes(pose_descriptors: Sequence[np.ndarray], edges: np.ndarray,
                           config: ClassConfig | None = None,
                           progress: Callable[[int], None] | None = None,
                           check_stop: Callable[[], None] | None = None) -> ClassResult:
    """Compute feature classes and per-pose visibility with Algorithm 6.3.

    Args:
        pose_descriptors: per sampled pose, ``(n_i, d)`` descriptors of all features
            of that pose (all its images concatenated); ``n_i`` may be 0. ``uint8``
            arrays (SIFT) stay ``uint8`` in memory; other dtypes are converted to float32.
        edges: ``(m, 2)`` int pose graph G (undirected).
        config: tau, gamma, ratio and workers; defaults of :class:`ClassConfig`.
        progress: Called with 1 after each chunk of pose pairs is matched; what it raises
            stops the matching (the pool's workers are terminated).
        check_stop: Called before each chunk and every half second while the pool
            matches; what it raises stops the matching likewise.

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
    chunks = chunk_by_first_pose(pairs, self_poses, config.workers if use_pool else 1)
    tau2 = float(config.tau) ** 2
    check2 = (float(config.symmetry_factor) * float(config.tau)) ** 2
    with single_threaded_blas():
        if use_pool and len(chunks) > 1:
            results = map_in_processes(
                match_chunk_in_worker,
                [(chunk_descriptors(descriptors, chunk_pairs, chunk_self), offsets,
                  chunk_pairs, chunk_self, tau2, config.ratio, check2)
                 for chunk_pairs, chunk_self in chunks],
                config.workers, initializer=init_worker, progress=progress,
                check_stop=check_stop)
        else:
            results = []
            for chunk_pairs, chunk_self in chunks:
                if check_stop is not None:
                    check_stop()
                results.append(match_chunk(descriptors, offsets, chunk_pairs, chunk_self,
                                           tau2, config.ratio, check2))
                if progress is not None:
                    progress(1)

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
