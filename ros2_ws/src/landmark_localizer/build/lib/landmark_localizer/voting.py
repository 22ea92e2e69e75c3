"""Finding the region from the current image: voting and geometric verification (7.1).

"The features visible in the current image can vote for the regions they belong to,
according to a membership relationship computed off-line. The region in which the
robot is will be assumed to be one of those with at least k votes" (7.1, 3.1.4).

:func:`vote`: every SIFT feature of the current image is matched to the class index
(each class's representative descriptors, through the index's FLANN forest; Lowe's
ratio against the nearest *other* class); each matched class votes for the regions it
belongs to (landmark or extra); candidates need ``vote_min_votes`` votes (default: the
database's k).

:func:`verify`: a candidate is checked geometrically: the image's features are matched
to each of the region's model views with the symmetry check the thesis suggests
(6.2.1: a match must also hold matched back from the model view), the motion to each
view is solved (:func:`vbn_common.geometry.two_view.relative_motion`) and the
rays intersected (:func:`~vbn_common.geometry.localize.position_from_views`);
a candidate passes with enough inliers per view, a bounded residual and rays that
meet in front of the views. The best candidate (most inliers) wins.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex, RegionData
from landmark_localizer.matching import mutual_matches
from landmark_localizer.pose import PoseSolution, solve_pose
from vbn_common.features import ImageFeatures

__all__ = ['REFUTATION_LIMIT', 'Candidate', 'Verified', 'agreeing', 'refutes', 'verify', 'vote']


@dataclass(frozen=True)
class Candidate:
    """A region with enough votes.

    Attributes:
        region: Region index.
        votes: Distinct matched classes of the region.
    """

    region: int
    votes: int


@dataclass(frozen=True)
class Verified:
    """A candidate that passed the geometric check.

    Attributes:
        region: Region index.
        solution: The pose solve against its model views.
        class_ids: (t,) classes matched in the current image (the tracks to start).
        uv: (t, 2) their pixels in the current image.
        judged: Whether the matched classes' 3-D points judged the pose (False: too few
            of them, in too narrow a cone, or their refinement failed: they cannot tell
            a wrong motion).
    """

    region: int
    solution: PoseSolution
    class_ids: np.ndarray
    uv: np.ndarray
    judged: bool = True


def vote(features: ImageFeatures, index: DatabaseIndex, config: LocalizerConfig,
         allowed: np.ndarray | None = None,
         nearest: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
         ) -> list[Candidate]:
    """Return the candidate regions, most votes first (at most ``vote_candidates``).

    Args:
        features: The current image's SIFT features.
        index: The database index.
        config: Voting settings.
        allowed: Region indices to consider (None: all).
        nearest: ``index.nearest_classes`` of the features, if already computed.
    """
    if len(features) == 0:
        return []
    best, d1, d_other = nearest if nearest is not None else \
        index.nearest_classes(features.descriptors, config.vote_checks)
    good = (best >= 0) & (d1 <= config.vote_max_distance) & (d1 < config.vote_ratio * d_other)
    matched = np.zeros(index.n_classes, np.float64)
    matched[np.unique(best[good])] = 1.0
    votes = np.asarray(index.membership.T @ matched).ravel().astype(int)
    need = config.vote_min_votes or index.k
    regions = np.flatnonzero(votes >= need)
    if allowed is not None:
        regions = np.intersect1d(regions, allowed)
    order = np.lexsort((regions, -votes[regions]))
    return [Candidate(int(r), int(votes[r])) for r in regions[order][:config.vote_candidates]]


def verify(features: ImageFeatures, region: RegionData, index: DatabaseIndex,
           config: LocalizerConfig, rng: np.random.Generator) -> Verified | None:
    """Check a candidate region geometrically; None when it fails."""
    query = features.descriptors.astype(np.float32)
    matched_uv: dict[int, np.ndarray] = {}
    for view in region.views:
        pairs = mutual_matches(query, view.descriptors, config.verify_ratio,
                               config.vote_max_distance)
        for i, j in pairs:
            matched_uv.setdefault(int(view.class_ids[j]), features.keypoints[i])
    if len(matched_uv) < config.min_inliers:
        return None
    class_ids = np.fromiter(matched_uv, np.int64, len(matched_uv))
    uv = np.array([matched_uv[int(c)] for c in class_ids], float)
    solution = solve_pose(index, region, class_ids, uv, config, rng)
    if solution is None:
        return None
    keep = np.isin(class_ids, solution.inlier_classes)
    return Verified(region.index, solution, class_ids[keep], uv[keep])


#: Squared Mahalanobis distance beyond which an absolute pose refutes a vote's: the
#: 99.9 % quantile of the chi-square with two degrees of freedom.
REFUTATION_LIMIT = 13.82


def agreeing(voted: PoseSolution, *poses: PoseSolution | None) -> PoseSolution | None:
    """Return the first of ``poses`` that does not refute the vote (None: none of them).

    A vote's pose is polished by the absolute pose found near it. In a changed room
    (``vbn bench-integrity``, room seed 1) that search found a look-alike 71 cm and 18
    degrees off a vote 7 cm off (its own standard deviation 15 cm), while the frame's own
    absolute pose was 1 cm off; the localizer published the look-alike. The polish must
    agree with the vote (:func:`refutes`), else the next pose is taken, else the vote's.

    Example:
        >>> from vbn_common.geometry.localize import PoseEstimate
        >>> def at(x): return PoseSolution(PoseEstimate(x, 0.0, 0.0, np.eye(3) * 1e-4,
        ...                                             0.5, 0.0, 2, True), np.zeros(0), 2, 9, 0.3)
        >>> agreeing(at(0.0), at(0.7), None, at(0.01)).estimate.x
        0.01
        >>> agreeing(at(0.0), at(0.7)) is None, agreeing(at(0.0)) is None
        (True, True)
    """
    return next((p for p in poses if p is not None and not refutes(p, voted)), None)


def refutes(absolute: PoseSolution | None, voted: PoseSolution) -> bool:
    """Whether a frame's absolute pose refutes a vote its class points could not judge.

    A vote's two-view pose that too few class points, or points in too narrow a cone,
    could judge may be a wrong motion: on a run whose camera stood 5 cm above the
    exploration's, after 35 frames posed from the class points within a centimetre, a
    vote confirmed by 5 of 6 points within 4 degrees put the robot 78 cm off and
    tracking followed it for 11 frames. The pose from the class points (what a LOST
    frame publishes) refutes it when their positions differ beyond the 99.9 % bound of
    their covariances (:data:`REFUTATION_LIMIT`); without one nothing refutes it. The
    localizer asks this of the vote it would start from, LOST or recovering a loss, and
    prefers among a frame's candidates the ones their points judged.

    Example:
        >>> from vbn_common.geometry.localize import PoseEstimate
        >>> def at(x): return PoseSolution(PoseEstimate(x, 0.0, 0.0, np.eye(3) * 1e-4,
        ...                                             0.5, 0.0, 2, True), np.zeros(0), 2, 9, 0.3)
        >>> refutes(at(0.0), at(0.02)), refutes(at(0.0), at(0.2)), refutes(None, at(0.2))
        (False, True, False)
    """
    if absolute is None:
        return False
    a, b = absolute.estimate, voted.estimate
    d = np.asarray(b.pose[:2], float) - np.asarray(a.pose[:2], float)
    joint = np.asarray(a.covariance, float)[:2, :2] + np.asarray(b.covariance, float)[:2, :2]
    try:
        return bool(d @ np.linalg.solve(joint, d) > REFUTATION_LIMIT)
    except np.linalg.LinAlgError:
        return False
