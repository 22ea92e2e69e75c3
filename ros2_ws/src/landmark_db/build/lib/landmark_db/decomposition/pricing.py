"""Pricing for the lower bound of :mod:`.bound`: the heaviest candidate, anchor by anchor.

Given duals y >= 0 on the poses, find maximal candidates S (connected components of
{v : L subset of F~_v}, |L| = k) of weight y(S) > 1, or prove an upper bound U on
every candidate's weight (Farley's certificate in :mod:`.bound` divides by it).

A candidate of positive weight contains a pose of positive dual, its *anchor*. The
anchors are searched one after the other, heaviest dual first; the search of anchor
a only looks at candidates containing a, and once it ends a is *retired*: later
anchors look for candidates containing none of the retired anchors, so they search
the graph with the retired poses removed (a candidate avoiding them is connected in
that graph). That is exact and keeps each search local:

* its root is the component of a among the live poses sharing at least k features
  with a (every candidate containing a lies in it);
* a node is the component of a within the poses seeing a set C of a's features
  (bitsets over the poses, Python ints); its weight bounds every candidate below it,
  and so does the (k - |closure|)-th heaviest of its one-feature cuts;
* a node whose *closure* (features every pose of it sees) holds k features is a
  region; widened to the full component of its landmark it joins the pool.

When a search stops at its node limit, its open nodes' weights enter U, so the bound
stays valid however early it stops; anchors left once the round's nodes are spent
enter U with their root's weight. Pure Python over bitsets: meant for built worlds
of a few thousand poses.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from landmark_db.decomposition.problem import (
    ZeroProblem,
    ZeroRegion,
    component_of,
    gather_slices,
)

__all__ = ['AnchoredPricing', 'Priced']

_EPS = 1e-9
#: Floating-point sums: a weight within this of 1 counts as 1; U is at least 1 + it.
SLACK = 1e-7


@dataclass(frozen=True)
class Priced:
    """One pricing round.

    Attributes:
        regions: up to ``most`` candidates of weight above 1, heaviest first.
        upper: U, an upper bound on every candidate's weight (at least 1 + SLACK).
        proven: no candidate weighs more than 1 (the restricted LP is optimal).
        nodes: branch-and-bound nodes searched.
    """

    regions: list[ZeroRegion]
    upper: float
    proven: bool
    nodes: int


class AnchoredPricing:
    """The per-problem data of the search (feature supports, neighbours, shared sets)."""

    def __init__(self, problem: ZeroProblem) -> None:
        self.problem = problem
        n = problem.n_poses
        csc = problem.visible_csc
        self.supports = [_bits(csc.indices[csc.indptr[c]:csc.indptr[c + 1]])
                         for c in range(problem.n_features)]
        adjacency = problem.adjacency
        self.neighbours = [_bits(adjacency.indices[adjacency.indptr[v]:adjacency.indptr[v + 1]])
                           for v in range(n)]
        self._shared: dict[int, int] = {}

    def shared(self, anchor: int) -> int:
        """Return the poses sharing at least k features with ``anchor`` (bits, cached)."""
        bits = self._shared.get(anchor)
        if bits is None:
            csc = self.problem.visible_csc
            rows, _ = gather_slices(csc.indptr, csc.indices, self.problem.row_features(anchor))
            counts = np.bincount(rows, minlength=self.problem.n_poses)
            bits = self._shared[anchor] = _bits(np.flatnonzero(counts >= self.problem.k))
        return bits

    def price(self, duals: np.ndarray, node_limit: int, anchor_limit: int = 5_000,
              most: int = 200, check_stop: Callable[[], None] | None = None) -> Priced:
        """Search every anchor's candidates (see the module docstring).

        Args:
            duals: (n,) non-negative pose duals.
            node_limit: most nodes over all anchors this round.
            anchor_limit: most nodes for one anchor.
            most: most candidates returned.
            check_stop: called every 1,024 nodes; what it raises ends the search.
        """
        problem = self.problem
        k, n = problem.k, problem.n_poses
        weighted = np.flatnonzero(duals > _EPS)
        weight_of_bit = {int(v): float(duals[v]) for v in weighted}
        weighted_mask = _bits(weighted)

        def weight(bits: int) -> float:
            total, rest = 0.0, bits & weighted_mask
            while rest:
                low = rest & -rest
                total += weight_of_bit[low.bit_length() - 1]
                rest ^= low
            return total

        def component(anchor: int, bits: int) -> int:
            comp = frontier = 1 << anchor
            while frontier:
                grown = 0
                rest = frontier
                while rest:
                    low = rest & -rest
                    grown |= self.neighbours[low.bit_length() - 1]
                    rest ^= low
                frontier = grown & bits & ~comp
                comp |= frontier
            return comp

        live = (1 << n) - 1
        found: dict[bytes, tuple[float, ZeroRegion]] = {}
        heaviest, open_bound, nodes = 0.0, 0.0, 0
        threshold = 1.0 + SLACK
        anchors = weighted[np.argsort(-duals[weighted], kind='stable')].tolist()
        for anchor in anchors:
            if nodes >= node_limit:
                # Unsearched: its root's weight bounds its candidates.
                open_bound = max(open_bound, weight(self.shared(anchor) & live))
                live &= ~(1 << anchor)
                continue
            root = component(anchor, self.shared(anchor) & live)
            root_weight = weight(root)
            if root_weight > threshold:
                features = problem.row_features(anchor).tolist()
                cut = {c: weight(self.supports[c] & root) for c in features}
                heavy = sorted((c for c in features if cut[c] > threshold),
                               key=lambda c: -cut[c])
                stack = [(root_weight, root, [], heavy)]
                visited: set[int] = {root}
                start = nodes
                while stack:
                    node_weight, bits, closed, tail = stack.pop()
                    if node_weight <= threshold:
                        continue
                    if nodes - start >= anchor_limit or nodes >= node_limit:
                        open_bound = max(open_bound, node_weight)
                        continue
                    nodes += 1
                    if check_stop is not None and nodes % 1024 == 0:
                        check_stop()
                    comp = component(anchor, bits)
                    comp_weight = weight(comp)
                    if comp_weight <= threshold:
                        continue
                    closed = closed + [c for c in tail if comp & self.supports[c] == comp]
                    if len(closed) >= k:
                        heaviest = max(heaviest, comp_weight)
                        if comp_weight > 1.0 + SLACK:
                            landmark = np.sort(np.asarray(closed[:k], dtype=np.int64))
                            region = component_of(problem.adjacency,
                                                  problem.poses_seeing_all(landmark), anchor)
                            found.setdefault(region.tobytes(), (float(duals[region].sum()),
                                                                ZeroRegion(region, landmark)))
                        # Keep collecting columns close to the heaviest, prune the rest.
                        threshold = max(1.0 + SLACK, 0.7 * heaviest)
                        continue
                    cuts = []
                    for c in tail:
                        child = comp & self.supports[c]
                        if child == comp:
                            continue
                        child_weight = weight(child)
                        if child_weight > threshold:
                            cuts.append((child_weight, c, child))
                    need = k - len(closed)
                    if len(cuts) < need:
                        continue
                    cuts.sort(key=lambda item: -item[0])
                    limit = cuts[need - 1][0]
                    if limit <= threshold:
                        continue
                    viable = [c for _, c, _ in cuts]
                    children = []
                    for child_weight, _, child in cuts:
                        if child in visited:
                            continue
                        visited.add(child)
                        children.append((min(child_weight, limit), child, closed, viable))
                    children.sort(key=lambda item: item[0])
                    stack.extend(children)
            live &= ~(1 << anchor)
        best = sorted(found.values(), key=lambda item: -item[0])[:most]
        upper = max(heaviest, open_bound, 1.0 + SLACK)
        return Priced([region for _, region in best], upper,
                      open_bound == 0.0 and heaviest <= 1.0 + SLACK, nodes)


def _bits(indices: np.ndarray) -> int:
    """Python int with the given bit positions set."""
    value = 0
    for i in np.asarray(indices, dtype=np.int64).tolist():
        value |= 1 << i
    return value
