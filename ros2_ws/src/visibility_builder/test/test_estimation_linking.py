"""Pieces joined by the consensus of their pairs, and the odometry's path between images.

Hand-made pieces: piece B's estimate is off the truth by a known rigid correction; pairs
measured from the truth agree on that correction, wrong pairs do not.
"""
from __future__ import annotations

import math
from pathlib import Path

from exploration_samples import POSE, T0, pose, write_bag
import numpy as np
import pytest

from vbn_common.geometry.frames import compose_poses, invert_pose, transform_points
from visibility_builder.estimation.linking import (
    MIN_LINK_PAIRS,
    LinkBound,
    colocated,
    consensus,
    join_pieces,
    link_bounds,
    link_candidates,
)
from visibility_builder.estimation.odometry_path import odometry_steps, straight_steps
from visibility_builder.estimation.rotations import quat_from_yaw, quat_to_matrix
from visibility_builder.estimation.view_pairs import PairMotion


def _rigid(poses: np.ndarray, rotation: float, translation: np.ndarray) -> np.ndarray:
    out = poses.copy()
    out[:, :2] = transform_points(np.array([*translation, rotation]), poses[:, :2])
    out[:, 2] = poses[:, 2] + rotation
    return out


def _pair(i: int, j: int, truth: np.ndarray, turn_error: float = 0.0,
          bearing_error: float = 0.0) -> PairMotion:
    rel = compose_poses(invert_pose(truth[i]), truth[j])
    rotation = quat_to_matrix(quat_from_yaw(np.array([-(rel[2] + turn_error)])))[0]
    bearing = math.atan2(rel[1], rel[0]) + bearing_error
    return PairMotion(i, j, rotation, np.array([math.cos(bearing), math.sin(bearing), 0.0]),
                      1e-4, 1e-3, 60, 50, 1e-3, 'panoramic_planar')


@pytest.fixture
def two_rooms() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth, estimate (room B turned 4 deg and moved) and pieces of two 3 x 3 rooms."""
    rng = np.random.default_rng(3)
    xy = np.array([(x, y) for x in range(3) for y in range(3)], float) * 0.5
    truth = np.concatenate([np.c_[xy, rng.uniform(-3, 3, 9)],
                            np.c_[xy + [0.0, 2.0], rng.uniform(-3, 3, 9)]])
    pieces = np.repeat([0, 1], 9)
    estimate = truth.copy()
    estimate[9:] = _rigid(truth[9:], math.radians(4.0), np.array([0.1, -0.15]))
    return truth, estimate, pieces


def test_the_pairs_agree_on_the_correction_that_undoes_the_drift(two_rooms) -> None:
    truth, estimate, pieces = two_rooms
    right = [_pair(i, j, truth) for i in (0, 3, 6, 2) for j in (9, 12, 15)]
    wrong = [_pair(1, 10, truth, turn_error=0.3), _pair(4, 13, truth, bearing_error=2.0),
             _pair(7, 16, truth, turn_error=-0.2, bearing_error=1.0)]
    link = consensus(estimate, pieces == 0, right + wrong, np.random.default_rng(0))
    assert link is not None
    assert sorted(link.inliers.tolist()) == list(range(len(right)))
    corrected = _rigid(estimate[9:], link.rotation, link.translation)
    assert np.abs(corrected[:, :2] - truth[9:, :2]).max() < 1e-6
    assert np.abs(corrected[:, 2] - truth[9:, 2]).max() < 1e-9
    # The same pairs numbered the other way round (view of B first) say the same.
    flipped = [_pair(p.j, p.i, truth) for p in right]
    other = consensus(estimate, pieces == 0, flipped, np.random.default_rng(0))
    assert other is not None and abs(other.rotation - link.rotation) < 1e-9


def test_too_few_or_parallel_pairs_join_nothing(two_rooms) -> None:
    truth, estimate, pieces = two_rooms
    few = [_pair(i, j, truth) for i, j in ((0, 9), (3, 12), (6, 15), (2, 11))]
    assert len(few) < MIN_LINK_PAIRS
    assert consensus(estimate, pieces == 0, few, np.random.default_rng(0)) is None
    # A corridor: every bearing along y, so the pairs do not fix a shift along it.
    parallel = [_pair(i, i + 9, truth) for i in range(9)]
    assert consensus(estimate, pieces == 0, parallel, np.random.default_rng(0)) is None


def test_a_look_alike_rival_is_refused_unless_the_odometry_tells_them_apart(two_rooms) -> None:
    truth, estimate, pieces = two_rooms
    right = [_pair(i, j, truth) for i in (0, 3, 6) for j in (9, 12, 15)]
    # A look-alike: the same room B as if it stood 1 m aside and turned 30 degrees.
    ghost = truth.copy()
    ghost[9:] = _rigid(truth[9:], math.radians(30.0), np.array([1.0, 0.0]))
    rival = [_pair(i, j, ghost) for i in (2, 5, 8) for j in (11, 14, 17)]
    rng = np.random.default_rng(0)
    assert consensus(estimate, pieces == 0, right + rival, rng) is None
    bound = LinkBound(math.radians(10.0), 0.5, estimate[9:, :2])
    link = consensus(estimate, pieces == 0, right + rival, np.random.default_rng(0),
                     bound=bound)
    assert link is not None and sorted(link.inliers.tolist()) == list(range(len(right)))
    # A bound too tight for the truth joins nothing.
    tight = LinkBound(math.radians(1.0), 0.05, estimate[9:, :2])
    assert consensus(estimate, pieces == 0, right, np.random.default_rng(0),
                     bound=tight) is None


def test_colocated_pairs_the_views_a_correction_puts_at_one_place() -> None:
    camera = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0],        # piece A
                       [2.1, 0.0, 0.5], [5.0, 5.0, 0.0], [1.9, 0.2, 0.0]])
    piece_a = np.array([True, True, False, False, False])
    # Moved 1 m back, view 2 lands 0.1 m from view 1; view 4 0.2 m from view 0's
    # neighbour 1 too (0.9, 0.2): 0.22 m; view 3 far from both.
    assert colocated(camera, piece_a, ~piece_a, 0.0, np.array([-1.0, 0.0])) == \
        [(1, 2), (1, 4)]
    # At most one check: the first of piece B's views in order.
    assert colocated(camera, piece_a, ~piece_a, 0.0, np.array([-1.0, 0.0]), most=1) == \
        [(1, 2)]
    # A 90 degree camera: view 2 looks 29 degrees away from view 1, view 4 the same way.
    assert colocated(camera, piece_a, ~piece_a, 0.0, np.array([-1.0, 0.0]),
                     field_deg=40.0) == [(1, 4)]
    assert colocated(camera, piece_a, ~piece_a, 0.0, np.array([5.0, 0.0])) == []


def test_a_correction_that_stacks_views_seeing_different_scenes_is_refused(two_rooms
                                                                             ) -> None:
    truth, estimate, pieces = two_rooms
    right = [_pair(i, j, truth) for i in (0, 3, 6) for j in (9, 12, 15)]
    # A look-alike better supported than the truth: room B as if it stood turned by
    # 20 degrees and 1.5 m lower, on room A.
    ghost = truth.copy()
    ghost[9:] = _rigid(truth[9:], math.radians(20.0), np.array([0.885, -1.52]))
    rival = [_pair(i, j, ghost) for i in (0, 2, 6, 8) for j in (9, 11, 15)]
    assert consensus(estimate, pieces == 0, right + rival, np.random.default_rng(0)) is None

    def probe(pairs: list[tuple[int, int]]) -> list[PairMotion | None]:
        # The world: views match when they truly stand within a metre of each other.
        return [_pair(i, j, truth) if np.hypot(*(truth[i, :2] - truth[j, :2])) < 1.0
                else None for i, j in pairs]

    added = join_pieces(estimate, pieces, right + rival, seed=1, probe=probe)
    assert {(p.i, p.j) for p in added} == {(p.i, p.j) for p in right}
    # Views that do stand at one place and match do not refuse the truth.
    stacked = truth.copy()
    stacked[9:, 1] -= 1.5
    moved = _rigid(stacked[9:], math.radians(4.0), np.array([0.1, -0.15]))
    again = np.concatenate([estimate[:9], moved])
    near = [_pair(i, j, stacked) for i in (0, 3, 6, 2) for j in (9, 12, 15)]
    kept = join_pieces(again, pieces, near, seed=1,
                       probe=lambda pairs: [_pair(i, j, stacked) for i, j in pairs])
    assert len(kept) == len(near)


def test_join_pieces_groups_pairs_by_the_pieces_they_join(two_rooms) -> None:
    truth, estimate, pieces = two_rooms
    inside = [_pair(0, 1, truth), _pair(9, 10, truth)]
    across = [_pair(i, j, truth) for i in (0, 3, 6, 2) for j in (9, 12, 15)]
    added = join_pieces(estimate, pieces, inside + across, seed=1)
    assert {(p.i, p.j) for p in added} == {(p.i, p.j) for p in across}


def test_the_bound_adds_the_variances_along_the_cheapest_chain_of_steps() -> None:
    # Views of pieces 0, 1, 0, 2: piece 2 hangs on piece 0 by step 2 -> 3 alone.
    pieces = np.array([0, 1, 0, 2])
    camera = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [5.0, 5.0, 0.0]])
    xy_std = np.array([0.1, 0.2, 0.3])
    yaw_std = np.array([0.01, 0.02, 0.04])
    bound = link_bounds(camera, pieces, 0, 2, xy_std, yaw_std)
    assert bound.turn == pytest.approx(3 * 0.04 + math.radians(1.0))
    assert bound.shift == pytest.approx(3 * 0.3 + 0.05)
    np.testing.assert_allclose(bound.anchors, [[5.0, 5.0]])
    # Piece 1 hangs by two steps (0 -> 1 and 1 -> 0): the lighter one bounds it.
    one = link_bounds(camera, pieces, 0, 1, xy_std, yaw_std)
    assert one.shift == pytest.approx(3 * 0.1 + 0.05)


def test_candidates_pair_views_of_different_pieces_within_the_radius() -> None:
    camera = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [1.0, 0.0, 0.0], [4.0, 0.0, 0.0],
                       [np.nan, np.nan, np.nan]])
    pieces = np.array([0, 0, 1, 1, 1])
    pairs = link_candidates(camera, pieces, radius_m=1.5, per_view=6)
    assert pairs == [(0, 2), (1, 2)]
    assert link_candidates(camera, np.zeros(5, int), radius_m=9.0) == []
    # A camera with a 90 degree field pairs only views within 45 degrees of each other.
    camera[2, 2] = 1.0
    assert link_candidates(camera, pieces, radius_m=1.5, field_deg=90.0) == []


def test_the_odometry_path_between_images_counts_the_detour(tmp_path: Path) -> None:
    # Images at (0, 0) and (1, 0); the odometry between them drives round a corner:
    # (0, 0) -> (0, 1) -> (1, 1) -> (1, 0), turning a quarter at each corner.
    track = [(0.0, 0.0, 0.0), (0.0, 0.5, math.pi / 2), (0.0, 1.0, math.pi / 2),
             (1.0, 1.0, 0.0), (1.0, 0.0, -math.pi / 2)]
    messages = [('/odom', POSE, T0 + k * 10**8, pose(T0 + k * 10**8, *p))
                for k, p in enumerate(track)]
    bag = write_bag(tmp_path / 'odom', messages)
    stamps = np.array([T0, T0 + 4 * 10**8])
    ends = np.array([track[0], track[-1]])
    steps = odometry_steps(bag, stamps, ends)
    np.testing.assert_allclose(steps, [[3.0, 2.0 * math.pi / 2 + math.pi / 2]])
    np.testing.assert_allclose(straight_steps(ends), [[1.0, math.pi / 2]])
    # Without the stream: the straight lines.
    empty = write_bag(tmp_path / 'none', [('/other', POSE, T0, pose(T0, 0.0, 0.0, 0.0))])
    np.testing.assert_allclose(odometry_steps(empty, stamps, ends), straight_steps(ends))


def test_most_pairs_beyond_the_bound_overrule_it_when_the_views_at_one_place_confirm() -> None:
    """The odometry's bound too tight for the truth (three times its drift): the images win.

    Room B's views stand between room A's (0.35 m from the nearest), so the true
    correction puts views at one place, and only views that match there confirm it.
    """
    import functools

    from visibility_builder.estimation import linking

    xy = np.array([(x, y) for x in range(3) for y in range(3)], float) * 0.5
    rng = np.random.default_rng(5)
    truth = np.concatenate([np.c_[xy, rng.uniform(-3, 3, 9)],
                            np.c_[xy + 0.25, rng.uniform(-3, 3, 9)]])
    pieces = np.repeat([0, 1], 9)
    estimate = truth.copy()
    estimate[9:] = _rigid(truth[9:], math.radians(6.0), np.array([1.2, -0.6]))
    pairs = [_pair(i, j, truth) for i in range(9) for j in range(9, 18)]
    tight = LinkBound(math.radians(2.0), 0.3, estimate[9:, :2])
    asked: list[tuple[int, int]] = []

    def check(turn_error: float):
        def probe(which):
            asked.extend(which)
            return [_pair(i, j, truth, turn_error=turn_error) for i, j in which]
        return functools.partial(linking._contradicted, estimate, pieces == 0, pieces == 1,
                                 probe=probe, field_deg=360.0)

    # Without views to confirm it, the bound stands.
    assert consensus(estimate, pieces == 0, pairs, np.random.default_rng(0), bound=tight) is None
    link = consensus(estimate, pieces == 0, pairs, np.random.default_rng(0), bound=tight,
                     check=check(0.0))
    assert link is not None and len(link.inliers) == len(pairs)
    assert not tight.allows(link.rotation, link.translation)
    corrected = _rigid(estimate[9:], link.rotation, link.translation)
    assert np.abs(corrected[:, :2] - truth[9:, :2]).max() < 1e-6
    assert len(asked) >= 3 and all(np.linalg.norm(truth[i, :2] - truth[j, :2]) < 0.4
                                   for i, j in asked)
    # Views at one place that turn otherwise refuse it.
    assert consensus(estimate, pieces == 0, pairs, np.random.default_rng(0), bound=tight,
                     check=check(0.3)) is None
    # Fewer than most pairs beyond the bound: the bound stands.
    few = pairs[:30] + [_pair(i, j, truth, bearing_error=1.0 + 0.05 * k)
                        for k, (i, j) in enumerate((i, j) for i in range(9)
                                                   for j in range(9, 18))][30:]
    assert consensus(estimate, pieces == 0, few, np.random.default_rng(0), bound=tight,
                     check=check(0.0)) is None
