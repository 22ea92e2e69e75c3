"""Pairs that join the pieces of an estimate, kept by their consensus (beyond thesis 6.1).

The thesis pairs views by their overlap (Algorithm 6.1) and trusts each pair that one
motion explains. A robot that drives from one room into the next records few views
that see both: on the 25 cm floor each room's views are joined well among themselves,
and a room hangs on the corridor by the odometry of the drive through its door alone,
which turns it by 5 to 15 degrees (the default drift). Views on either side of the door
do overlap (1 to 2 m apart through the opening: 670 of 3,044 such pairs measured, their
rotations 0.04 to 0.15 degrees off at the median), but 10 to 30 % of them are wrong
(a second motion that fits few matches as well), and the estimate cannot judge them one
by one: it is as far off as the drift that the pairs are there to remove.

So the pairs between two pieces are judged together (the consensus that RANSAC gives
a two-view fit, here over the rigid correction of one piece against the other, as
loop-closure checks in pose-graph SLAM do): every correct pair says the same thing,
the planar motion ``(rotation, translation)`` that moves piece B onto piece A, and a
wrong pair says something else. :func:`link_candidates` proposes pairs between pieces
near in the estimate, :func:`consensus` keeps the largest set that agrees on one
correction, and only when enough distinct views on both sides support it. A
correction must also put no two views at one place that do not see the same scene
(:func:`colocated`): the look-alike posters of two rooms agree on a wrong correction as
well as a door does on the right one, and only the views it stacks on each other show it.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import functools
import logging
import math

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from vbn_common.geometry.frames import transform_points, wrap_angle
from visibility_builder.estimation.rotations import matrix_to_quat, quat_yaw
from visibility_builder.estimation.view_pairs import PairMotion

_LOG = logging.getLogger(__name__)

__all__ = ['MIN_LINK_PAIRS', 'LinkBound', 'LinkCorrection', 'colocated', 'consensus',
           'join_pieces', 'link_bounds', 'link_candidates', 'near_pairs']

#: A correction between two pieces needs this many agreeing pairs, with at least
#: ``MIN_LINK_VIEWS`` distinct views on each side.
MIN_LINK_PAIRS = 8
MIN_LINK_VIEWS = 3
#: Agreement: a pair's rotation within this of the correction's (or three of its
#: standard deviations), degrees; its bearing within ``DIRECTION_TOL_DEG``.
ROTATION_TOL_DEG = 0.5
DIRECTION_TOL_DEG = 1.5
#: The agreeing pairs' bearings must spread this much (RMS, degrees): along parallel
#: bearings (a corridor) the pairs do not fix the correction, and pairs through a wall
#: between two look-alike posters join those through a door on one wrong correction.
MIN_SPREAD_DEG = 10.0
#: A second correction agreed on by at least this share of the first's pairs (and by
#: other pairs) makes the link ambiguous.
RIVAL_SHARE = 0.4
#: A correction beyond the odometry's bound overrules it when most of the pairs agree on
#: it and at least this many times as many as on the best correction within the bound.
OVERRULE = 4.0
#: Views of two pieces this close once corrected stand at one place (closer than twice
#: the distance a robot keeps from a wall, so no wall between them): they see one scene
#: and must match, their rotation the correction's. At most ``COLOCATED_CHECKS`` such
#: pairs are measured per correction; it is refused when at least
#: ``MIN_CONTRADICTIONS`` and most of them contradict it.
COLOCATED_M = 0.25
#: ... and a correction beyond the odometry's bound is confirmed by views this close
#: (still less than two wall clearances and a wall: no wall between them).
CONFIRM_M = 0.4
COLOCATED_CHECKS = 12
MIN_CONTRADICTIONS = 3

#: Measures pairs ``(i, j)``, ``i < j``: a motion each, or None where they do not match.
Probe = Callable[[list[tuple[int, int]]], list[PairMotion | None]]


def link_candidates(camera: np.ndarray, pieces: np.ndarray, radius_m: float,
                    per_view: int = 6, field_deg: float = 360.0) -> list[tuple[int, int]]:
    """Return pairs ``(i, j)``, ``i < j``, of views in different pieces near in the estimate.

    Each view is paired with its ``per_view`` nearest views of every other piece within
    ``radius_m`` (so that the pairs spread along the pieces' boundary instead of piling
    up where it is narrowest); a camera that does not see all around pairs only views
    whose headings are within half its field.

    Args:
        camera: ``(n, 3)`` estimated camera poses ``(x, y, yaw)`` (NaN rows: no estimate).
        pieces: ``(n,)`` each view's piece.
        radius_m: How far apart in the estimate.
        per_view: Nearest views per view and other piece.
        field_deg: The camera's horizontal field, degrees (360: panoramic).
    """
    ok = np.flatnonzero(np.isfinite(camera).all(axis=1))
    labels = np.unique(pieces[ok])
    if len(labels) < 2:
        return []
    found = []
    for q in labels:
        others = ok[pieces[ok] == q]
        members = ok[pieces[ok] != q]
        dist, idx = cKDTree(camera[others, :2]).query(
            camera[members, :2], k=min(per_view, len(others)), distance_upper_bound=radius_m)
        dist, idx = dist.reshape(len(members), -1), idx.reshape(len(members), -1)
        row, col = np.nonzero(np.isfinite(dist))
        found.append(np.stack([members[row], others[idx[row, col]]], axis=1))
    pairs = np.sort(np.concatenate(found), axis=1)
    if field_deg < 360.0:
        turn = np.abs(wrap_angle(camera[pairs[:, 1], 2] - camera[pairs[:, 0], 2]))
        pairs = pairs[turn <= math.radians(0.5 * field_deg)]
    return [(int(i), int(j)) for i, j in np.unique(pairs, axis=0)]


def _moved(points: np.ndarray, rotation: float, translation: np.ndarray) -> np.ndarray:
    """Return ``points`` turned by ``rotation`` about the origin, then translated."""
    return transform_points(np.array([translation[0], translation[1], rotation]), points)


@dataclass(frozen=True)
class LinkBound:
    """How far the estimate can place one piece off another: what the odometry allows.

    Attributes:
        turn: Largest rotation of a correction, radians.
        shift: Largest displacement of a correction at any of ``anchors``, metres.
        anchors: ``(m, 2)`` where the moving piece hangs on the odometry (its views at
            the steps that join it to the other pieces).
    """

    turn: float
    shift: float
    anchors: np.ndarray

    def size(self, rotation: float, translation: np.ndarray) -> float:
        """Return the correction's turn and shift as shares of the bound (the larger)."""
        moved = _moved(self.anchors, rotation, translation) - self.anchors
        return max(abs(rotation) / self.turn,
                   float(np.min(np.linalg.norm(moved, axis=1))) / self.shift)

    def allows(self, rotation: float, translation: np.ndarray) -> bool:
        """Return whether the correction turns and moves the piece within the bound."""
        return self.size(rotation, translation) <= 1.0


@dataclass(frozen=True)
class LinkCorrection:
    """The rigid planar correction of one piece against another that pairs agree on.

    Attributes:
        rotation: Radians, about the ``map`` origin.
        translation: ``(2,)`` metres, applied after the rotation.
        inliers: Indices (into the pairs judged) of the pairs that agree.
    """

    rotation: float
    translation: np.ndarray
    inliers: np.ndarray


def _constraints(camera: np.ndarray, in_a: np.ndarray, pairs: list[PairMotion]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per pair: the correction's rotation, a fixed point, a moving point, a ray angle.

    A pair ``(i, j)`` with ``i`` in piece A says piece B turns by
    ``yaw_i + theta_ij - yaw_j`` and that view ``j`` corrected lies on the ray from
    view ``i`` at ``yaw_i + bearing``; with ``i`` in B, the ray runs from ``j`` (in A)
    back towards ``i``.
    """
    i = np.array([p.i for p in pairs])
    j = np.array([p.j for p in pairs])
    theta = -quat_yaw(np.array([matrix_to_quat(p.rotation) for p in pairs]).reshape(-1, 4))
    bearing = np.array([math.atan2(p.direction[1], p.direction[0]) if p.has_direction
                        else math.nan for p in pairs])
    yaw_i, yaw_j = camera[i, 2], camera[j, 2]
    delta = np.where(in_a, yaw_i + theta - yaw_j, yaw_j - theta - yaw_i)
    fixed = np.where(in_a[:, None], camera[i, :2], camera[j, :2])
    moving = np.where(in_a[:, None], camera[j, :2], camera[i, :2])
    ray = np.where(in_a, yaw_i + bearing, yaw_j - theta + bearing + math.pi)
    std = np.array([p.rotation_std for p in pairs])
    return wrap_angle(delta), fixed, moving, ray, std


def _agree(rotation: float, translation: np.ndarray, delta: np.ndarray, fixed: np.ndarray,
           moving: np.ndarray, ray: np.ndarray, rot_tol: np.ndarray) -> np.ndarray:
    rot_ok = np.abs(wrap_angle(delta - rotation)) <= rot_tol
    moved = _moved(moving, rotation, translation) - fixed
    angle = np.abs(wrap_angle(np.arctan2(moved[:, 1], moved[:, 0]) - ray))
    dir_ok = np.isnan(ray) | (angle <= math.radians(DIRECTION_TOL_DEG))
    return rot_ok & dir_ok


def _spread(ray: np.ndarray) -> float:
    """Return how far the rays are from all parallel, radians.

    The angle whose sine is the smaller singular value of the rays' normals over the
    root of their count (their RMS spread about the mean direction).
    """
    ray = ray[~np.isnan(ray)]
    if len(ray) < 2:
        return 0.0
    normal = np.stack([-np.sin(ray), np.cos(ray)], axis=1)
    smallest = np.linalg.svd(normal, compute_uv=False)[-1] / math.sqrt(len(ray))
    return math.asin(min(1.0, float(smallest)))


def _translation(rotation: float, fixed: np.ndarray, moving: np.ndarray, ray: np.ndarray
                 ) -> np.ndarray | None:
    """Least-squares translation putting the moved points on their rays (None: too few)."""
    use = ~np.isnan(ray)
    if use.sum() < 2:
        return None
    normal = np.stack([-np.sin(ray[use]), np.cos(ray[use])], axis=1)
    rhs = np.sum(normal * (fixed[use] - _moved(moving[use], rotation, np.zeros(2))), axis=1)
    if np.linalg.matrix_rank(normal, tol=1e-3) < 2:
        return None
    return np.linalg.lstsq(normal, rhs, rcond=None)[0]


def colocated(camera: np.ndarray, piece_a: np.ndarray, piece_b: np.ndarray,
              rotation: float, translation: np.ndarray, field_deg: float = 360.0,
              radius_m: float = COLOCATED_M, most: int = COLOCATED_CHECKS
              ) -> list[tuple[int, int]]:
    """Return pairs ``(i, j)``, ``i < j``, of views the correction puts at one place.

    Each view of piece B, corrected, with the nearest view of piece A within
    ``radius_m`` (a camera that does not see all around: headings within half its
    field); at most ``most`` of them, evenly through piece B's views.
    """
    a = np.flatnonzero(piece_a & np.isfinite(camera).all(axis=1))
    b = np.flatnonzero(piece_b & np.isfinite(camera).all(axis=1))
    if not len(a) or not len(b):
        return []
    moved = _moved(camera[b, :2], rotation, translation)
    dist, near = cKDTree(camera[a, :2]).query(moved, distance_upper_bound=radius_m)
    keep = np.isfinite(dist)
    if field_deg < 360.0:
        turn = wrap_angle(camera[b, 2] + rotation - camera[a[np.minimum(near, len(a) - 1)], 2])
        keep &= np.abs(turn) <= math.radians(0.5 * field_deg)
    rows = np.flatnonzero(keep)
    rows = rows[np.unique(np.linspace(0, len(rows) - 1, min(most, len(rows))).astype(int))] \
        if len(rows) else rows
    pairs = np.sort(np.stack([a[near[rows]], b[rows]], axis=1), axis=1)
    return [(int(i), int(j)) for i, j in pairs]


def _contradicted(camera: np.ndarray, piece_a: np.ndarray, piece_b: np.ndarray,
                  link: LinkCorrection, probe: Probe, field_deg: float,
                  confirm: bool = False) -> str:
    """Return why the views the correction puts at one place refuse it, or ''.

    With ``confirm`` (a correction beyond the odometry's bound), at least
    ``MIN_CONTRADICTIONS`` such views must match and turn as it says, and most of them.
    """
    pairs = colocated(camera, piece_a, piece_b, link.rotation, link.translation, field_deg,
                      radius_m=CONFIRM_M if confirm else COLOCATED_M)
    if not pairs:
        return 'no views it puts at one place confirm it' if confirm else ''
    found = [m for m in probe(pairs) if m is not None]
    agree = 0
    if found:
        delta, _, _, _, std = _constraints(camera, piece_a[[m.i for m in found]], found)
        tol = np.maximum(math.radians(ROTATION_TOL_DEG), 3.0 * std)
        agree = int(np.sum(np.abs(wrap_angle(delta - link.rotation)) <= tol))
    against = len(pairs) - agree
    if against >= MIN_CONTRADICTIONS and against > 0.5 * len(pairs):
        return f'{against} of {len(pairs)} views it puts at one place do not match'
    if confirm and (agree < MIN_CONTRADICTIONS or agree <= 0.5 * len(pairs)):
        return f'only {agree} of {len(pairs)} views it puts at one place confirm it'
    return ''


def consensus(camera: np.ndarray, piece_a: np.ndarray, pairs: list[PairMotion],
              rng: np.random.Generator, hypotheses: int = 300,
              bound: LinkBound | None = None,
              check: Callable[[LinkCorrection], str] | None = None
              ) -> LinkCorrection | None:
    """Return the correction most pairs between two pieces agree on, or None.

    Hypotheses are drawn from two pairs whose rotations agree (RANSAC); the best is
    refitted on the pairs it keeps (the circular mean of their rotations, then the
    translation by least squares) and kept when at least ``MIN_LINK_PAIRS`` pairs with
    ``MIN_LINK_VIEWS`` distinct views on each side agree. With a ``bound``, only
    corrections the odometry allows are hypotheses: the two sides of a thin wall with
    one texture agree as well as the two sides of a door (on the 0.75 m floor ten pairs
    through a wall, their bearings reversed, agreed on moving a room 2.34 m, against
    five through the door on the true correction), and only the odometry tells them
    apart.

    Args:
        camera: ``(n, 3)`` the estimate's camera poses.
        piece_a: ``(n,)`` bool, the views of the piece that stays.
        pairs: The measured pairs between the two pieces (each has one view in each).
        rng: Draws the hypotheses.
        hypotheses: How many.
        bound: How far the estimate can be off between the two pieces.
        check: Why a correction is refused ('' when not; :func:`join_pieces` checks the
            views it puts at one place); a refused one is neither kept nor a rival.
    """
    if len(pairs) < MIN_LINK_PAIRS:
        return None
    in_a = piece_a[np.array([p.i for p in pairs])]
    delta, fixed, moving, ray, std = _constraints(camera, in_a, pairs)
    rot_tol = np.maximum(math.radians(ROTATION_TOL_DEG), 3.0 * std)
    found: list[np.ndarray] = []
    beyond: list[np.ndarray] = []       # hypotheses the bound refuses
    for _ in range(hypotheses):
        a, b = rng.choice(len(pairs), 2, replace=False)
        if abs(float(wrap_angle(delta[a] - delta[b]))) > rot_tol[a] + rot_tol[b]:
            continue
        rotation = float(delta[a] + 0.5 * wrap_angle(delta[b] - delta[a]))
        two = np.array([a, b])
        translation = _translation(rotation, fixed[two], moving[two], ray[two])
        if translation is None:
            continue
        allowed = bound is None or bound.allows(rotation, translation)
        agree = _agree(rotation, translation, delta, fixed, moving, ray, rot_tol)
        if agree.sum() >= MIN_LINK_PAIRS:
            (found if allowed else beyond).append(agree)

    checked: dict[tuple[bytes, bool], LinkCorrection | None] = {}

    def refined(agree: np.ndarray, bounded: bool = True) -> LinkCorrection | None:
        key = (agree.tobytes(), bounded)
        if key not in checked:
            checked[key] = fitted(agree, bounded)
        return checked[key]

    def fitted(agree: np.ndarray, bounded: bool) -> LinkCorrection | None:
        for _ in range(3):
            if agree.sum() < MIN_LINK_PAIRS:
                return None
            rotation = float(np.angle(np.mean(np.exp(1j * delta[agree]))))
            translation = _translation(rotation, fixed[agree], moving[agree], ray[agree])
            if translation is None:
                return None
            agree = _agree(rotation, translation, delta, fixed, moving, ray, rot_tol)
        if bounded and bound is not None and not bound.allows(rotation, translation):
            return None
        views_a = {p.i if a else p.j for p, a, k in zip(pairs, in_a, agree) if k}
        views_b = {p.j if a else p.i for p, a, k in zip(pairs, in_a, agree) if k}
        if agree.sum() < MIN_LINK_PAIRS or min(len(views_a), len(views_b)) < MIN_LINK_VIEWS:
            return None
        if _spread(ray[agree]) < math.radians(MIN_SPREAD_DEG):
            return None
        link = LinkCorrection(rotation, translation, np.flatnonzero(agree))
        if not bounded and check is None:
            return None          # beyond the bound only with views that confirm it
        why = '' if check is None else check(link) if bounded else check(link, confirm=True)
        if why:
            _LOG.info('correction %.2f deg, %.2f m refused: %s', math.degrees(rotation),
                      float(np.linalg.norm(translation)), why)
            return None
        return link

    found.sort(key=lambda agree: -int(agree.sum()))
    best = next((link for link in map(refined, found) if link is not None), None)
    overruled = _overruled(best, beyond, len(pairs), bound,
                           lambda agree: refined(agree, bounded=False))
    if overruled is not None:
        return overruled
    if best is None:
        return None
    # A rival: another correction that other pairs agree on, nearly as well.
    taken = np.zeros(len(pairs), bool)
    taken[best.inliers] = True
    for agree in found:
        if (agree & taken).sum() > 0.2 * agree.sum() or \
                agree.sum() < RIVAL_SHARE * len(best.inliers):
            continue
        rival = refined(agree & ~taken)
        if rival is None or len(rival.inliers) < RIVAL_SHARE * len(best.inliers):
            continue
        # Two corrections: the one the odometry finds far more likely, else neither.
        if bound is None:
            return None
        ours = bound.size(best.rotation, best.translation)
        theirs = bound.size(rival.rotation, rival.translation)
        if theirs < 0.5 * ours:
            return rival
        return best if ours < 0.5 * theirs else None
    return best


def _overruled(best: LinkCorrection | None, beyond: list[np.ndarray], count: int,
               bound: LinkBound | None,
               refine: Callable[[np.ndarray], LinkCorrection | None]) -> LinkCorrection | None:
    """Return a correction beyond the bound that most pairs agree on, or None.

    The bound is the odometry's noise model, set for its default drift; a drive of 12 m
    at three times that drift left the last three views of the 25 cm floor 2 m further
    off than it allows, and the best correction within it (10 of 215 pairs) stacked them
    on the places 2 m away. When most of the pairs, and :data:`OVERRULE` times as many as
    agree on the best correction within the bound, agree on one beyond it, the images
    overrule the odometry, provided the views it puts at one place confirm it (the check
    of :func:`join_pieces` with ``confirm``; no check, no overruling). Through a thin wall
    with one texture on both sides, 10 pairs agreed on a wrong correction against 5
    through the door on the right one: not four times as many, and the views it stacks
    stand on either side of the wall.
    """
    if bound is None or not beyond:
        return None
    need = max(0.5 * count, OVERRULE * (len(best.inliers) if best is not None else 0.0))
    for agree in sorted(beyond, key=lambda a: -int(a.sum())):
        if agree.sum() < need:
            return None
        link = refine(agree)
        if link is not None and len(link.inliers) >= need and \
                not bound.allows(link.rotation, link.translation):
            _LOG.info("correction %.2f deg, %.2f m beyond the odometry's bound kept: %d of %d "
                      'pairs agree on it, %d on the best within it',
                      math.degrees(link.rotation), float(np.linalg.norm(link.translation)),
                      len(link.inliers), count, 0 if best is None else len(best.inliers))
            return link
    return None


def near_pairs(camera: np.ndarray, station: np.ndarray, radius_m: float, window: int,
               field_deg: float = 360.0) -> list[tuple[int, int]]:
    """Return pairs ``(i, j)``, ``i < j``, within ``radius_m`` in the estimate, far in time.

    Stations more than ``window`` apart (the first pass paired nearer ones); a camera
    that does not see all around pairs views whose headings are within half its field.
    """
    ok = np.flatnonzero(np.isfinite(camera).all(axis=1))
    if len(ok) < 2:
        return []
    pairs = np.sort(ok[cKDTree(camera[ok, :2]).query_pairs(radius_m, output_type='ndarray')],
                    axis=1).reshape(-1, 2)
    keep = station[pairs[:, 1]] - station[pairs[:, 0]] > window
    if field_deg < 360.0:
        turn = np.abs(wrap_angle(camera[pairs[:, 1], 2] - camera[pairs[:, 0], 2]))
        keep &= turn <= math.radians(0.5 * field_deg)
    return [(int(i), int(j)) for i, j in np.unique(pairs[keep], axis=0)]


def join_pieces(camera: np.ndarray, pieces: np.ndarray, motions: list[PairMotion],
                seed: int, step_std: tuple[np.ndarray, np.ndarray] | None = None,
                probe: Probe | None = None, field_deg: float = 360.0) -> list[PairMotion]:
    """Return the pairs of ``motions`` between two pieces that agree on one correction.

    The pairs are grouped by the two pieces they join; each group's :func:`consensus`
    keeps its agreeing pairs (none when too few agree), within the bound of
    :func:`link_bounds` when ``step_std`` (the odometry steps' displacement and turn
    deviations between consecutive views) is given, and refusing a correction when
    ``probe`` measures most of the views it puts at one place (:func:`colocated`) as
    not matching or turned otherwise.
    """
    groups: dict[tuple[int, int], list[PairMotion]] = {}
    for motion in motions:
        a, b = sorted((int(pieces[motion.i]), int(pieces[motion.j])))
        if a != b:
            groups.setdefault((a, b), []).append(motion)
    added = []
    for (a, b), group in sorted(groups.items()):
        bound = None if step_std is None else link_bounds(camera, pieces, a, b, *step_std)
        check = None if probe is None else functools.partial(
            _contradicted, camera, pieces == a, pieces == b, probe=probe, field_deg=field_deg)
        link = consensus(camera, pieces == a, group, np.random.default_rng([seed, a, b]),
                         bound=bound, check=check)
        if link is None:
            continue
        _LOG.info('pieces %d and %d joined by %d of %d pairs (correction %.2f deg, %.2f m)',
                  a, b, len(link.inliers), len(group), math.degrees(link.rotation),
                  float(np.linalg.norm(link.translation)))
        added += [group[k] for k in link.inliers]
    return added


def link_bounds(camera: np.ndarray, pieces: np.ndarray, a: int, b: int,
                step_xy_std: np.ndarray, step_yaw_std: np.ndarray,
                sigmas: float = 3.0) -> LinkBound:
    """Return how far the estimate can have placed piece ``b`` off piece ``a``.

    Pieces hang on each other by the odometry steps between consecutive views of two
    pieces; the chain of such steps from ``a`` to ``b`` with the least variance
    (Dijkstra over the pieces) bounds the error: ``sigmas`` of its summed turn and
    displacement deviations (their variances added along the chain), plus a degree and
    5 cm. The displacement is judged at ``b``'s views on those steps.
    """
    k = np.flatnonzero(pieces[:-1] != pieces[1:])
    count = int(pieces.max()) + 1
    if not len(k):
        return LinkBound(math.pi, math.inf, camera[pieces == b, :2])
    u, v = pieces[k], pieces[k + 1]

    def chain(weight: np.ndarray) -> float:
        least: dict[tuple[int, int], float] = {}       # the lighter of parallel steps
        for p, q, w in zip(u.tolist(), v.tolist(), weight.tolist()):
            key = (min(p, q), max(p, q))
            least[key] = min(least.get(key, math.inf), w + 1e-12)
        keys = np.array(list(least), np.int64).reshape(-1, 2)
        graph = coo_matrix((list(least.values()), (keys[:, 0], keys[:, 1])),
                           shape=(count, count)).tocsr()
        return float(dijkstra(graph, directed=False, indices=a)[b])

    turn_var = chain(step_yaw_std[k] ** 2)
    shift_var = chain(step_xy_std[k] ** 2)
    ends = np.concatenate([k[v == b] + 1, k[u == b]])
    anchors = camera[ends if len(ends) else np.flatnonzero(pieces == b), :2]
    return LinkBound(sigmas * math.sqrt(turn_var) + math.radians(1.0),
                     sigmas * math.sqrt(shift_var) + 0.05, anchors)
