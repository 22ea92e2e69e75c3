"""Default parameters of landmark_db, written once.

Function signatures, command-line options, help texts and the benchmark take their
defaults from here, so that a default changes in one line:

* :data:`DECOMPOSITION`: what :func:`~landmark_db.decomposition.decompose` and
  ``vbn decompose`` use unless told otherwise: no overlap (rho = 0), a complete
  decomposition (sigma = 0), the thesis's alpha = 0.85 for algorithm C, seed 0, and
  the set-cover time limits of ``exact`` and ``best``.
* :data:`THESIS`: the parameters of the thesis's synthetic experiment (Section 8.2,
  Tables 8.2-8.4): k = 4, rho = 1, sigma = 9, alpha = 0.85. ``vbn bench-decomposition``
  and the scaling run use them.
* :data:`POSE_SPACING`: the pose grid spacing of simulated worlds, 0.5 m as in
  Section 8.2.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

__all__ = ['DECOMPOSITION', 'POSE_SPACING', 'THESIS', 'DecompositionParameters']


@dataclass(frozen=True)
class DecompositionParameters:
    """The parameters of one decomposition (Chapters 4 and 5).

    Attributes:
        k: features per landmark. ``decompose`` and ``vbn decompose`` always require
            it; the default is the thesis's.
        rho: overlap radius in pose-graph steps (Chapter 4).
        sigma: a region is added only if it covers more than sigma otherwise
            uncovered poses (Section 5.5).
        alpha: algorithm C's least unassigned fraction of a neighbourhood N_r(v)
            (Section 5.3, Figure 5.3).
        seed: seed of the tie-breaking random generator.
        exact_time_limit: seconds HiGHS may take for ``exact``'s set cover.
        best_time_limit: seconds for each of ``best``'s set-cover MILPs.
    """

    k: int = 4
    rho: int = 0
    sigma: int = 0
    alpha: float = 0.85
    seed: int = 0
    exact_time_limit: float = 60.0
    best_time_limit: float = 5.0


DECOMPOSITION = DecompositionParameters()
THESIS = replace(DECOMPOSITION, k=4, rho=1, sigma=9)
POSE_SPACING = 0.5
