"""Service: the one coverage measure of a decomposition (Definitions 3.7 and 3.8).

A pose v is **k-coverable** when its rho-reduced visibility set F~_v (Theorem 4.1,
F_v itself when rho = 0) holds at least k features (Section 5.1). A k-coverable pose
is **served** when one region holds its whole rho-neighbourhood N_rho(v): that is
the rho-overlap property (Definition 3.7) which lets the localizer switch region
before the current landmark fades. The **service** of a decomposition is the share
of k-coverable poses it serves.

Plain membership (a k-coverable pose lying in some region, whatever its
neighbourhood) is reported beside it as ``in_region``; under rho = 0 the two agree.

Every command and report takes its figures from :func:`service`: ``vbn build``,
``vbn db-info``, ``vbn decompose``, ``vbn validate``, the build report's
``summary.json`` and the benchmarks.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.decomposition.coverable import coverable_poses
from landmark_db.decomposition.overlap import (
    covered_poses,
    neighbourhood_matrix,
    reduce_visibility,
)
from landmark_db.world import WorldInstance

__all__ = ['Service', 'service']


@dataclass(frozen=True, eq=False)
class Service:
    """How well a set of regions serves a world.

    Attributes:
        k: landmark size.
        rho: overlap radius.
        k_coverable: poses with |F~_v| >= k.
        served: k-coverable poses whose N_rho(v) lies inside one region.
        in_region: k-coverable poses lying in at least one region.
        unserved: sorted indices of the k-coverable poses that are not served.
        coverable_mask: ``(n,)`` bool, the k-coverable poses.
        served_mask: ``(n,)`` bool, the poses whose N_rho(v) lies inside one region
            (k-coverable or not).
    """

    k: int
    rho: int
    k_coverable: int
    served: int
    in_region: int
    unserved: np.ndarray = field(repr=False)
    coverable_mask: np.ndarray = field(repr=False)
    served_mask: np.ndarray = field(repr=False)

    @property
    def share(self) -> float:
        """Served share of the k-coverable poses (1.0 when there are none)."""
        return self.served / self.k_coverable if self.k_coverable else 1.0

    def to_dict(self) -> dict[str, Any]:
        """Return the JSON-ready figures (without the list of unserved poses)."""
        return {'k_coverable': self.k_coverable, 'served': self.served,
                'served_share': round(self.share, 6), 'unserved': int(self.unserved.size),
                'in_region': self.in_region}

    def describe(self) -> str:
        """One phrase, e.g. ``served 186 of 187 k-coverable poses (99.5 %)``."""
        return (f'served {self.served} of {self.k_coverable} k-coverable poses '
                f'({100.0 * self.share:.1f} %)')


def service(world: WorldInstance, regions: Sequence[np.ndarray], k: int, rho: int,
            coverable: np.ndarray | None = None,
            neighbourhoods: sp.csr_matrix | None = None) -> Service:
    """Measure the service of ``regions`` (pose index arrays) on ``world``.

    Args:
        world: the world instance.
        regions: each region's pose indices (any order; out-of-range indices are
            ignored, the validator reports them).
        k: landmark size.
        rho: overlap radius.
        coverable: the k-coverable mask if the caller has it (it must be the one of
            ``k`` and ``rho``); computed otherwise.
        neighbourhoods: N_rho rows (:func:`~.overlap.neighbourhood_matrix`) if the
            caller has them.

    Example:
        >>> import numpy as np
        >>> from landmark_db.world import grid_world
        >>> world = grid_world(3, 1, 0.5, np.ones((3, 2), bool))
        >>> s = service(world, [np.array([0, 1])], k=2, rho=1)
        >>> (s.k_coverable, s.served, s.in_region, s.unserved.tolist())
        (3, 1, 2, [1, 2])
    """
    n = world.n_poses
    if coverable is None:
        reduced = world.visible if rho == 0 else reduce_visibility(
            world.adjacency, world.visible, rho)
        coverable = coverable_poses(reduced, k)
    clean = [np.unique(poses[(poses >= 0) & (poses < n)]).astype(np.int64)
             for poses in (np.asarray(p, dtype=np.int64).reshape(-1) for p in regions)]
    member = np.zeros(n, dtype=bool)
    for poses in clean:
        member[poses] = True
    if rho == 0:
        served = member
    else:
        if neighbourhoods is None:
            neighbourhoods = neighbourhood_matrix(world.adjacency, rho)
        served = covered_poses(neighbourhoods, clean)
    return Service(k=int(k), rho=int(rho), k_coverable=int(coverable.sum()),
                   served=int(np.count_nonzero(coverable & served)),
                   in_region=int(np.count_nonzero(coverable & member)),
                   unserved=np.flatnonzero(coverable & ~served).astype(np.int64),
                   coverable_mask=coverable, served_mask=served)
