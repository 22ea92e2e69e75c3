"""Tests of landmark_db.geometry2d: point and segment distances, crossing predicates."""
from __future__ import annotations

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_db.geometry2d import (
    nearest_segment_distance,
    point_segment_distance,
    segment_distance,
    segments_blocked,
    segments_cross,
)
from landmark_db.scene import Scene

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [0.0, 1.0]])


def test_point_segment_distance_hand_checked() -> None:
    s0, s1 = np.array([0.0, 0.0]), np.array([2.0, 0.0])
    points = np.array([[1.0, 3.0],    # above the middle: perpendicular distance
                       [-3.0, 4.0],   # beyond the start: distance to the start (5)
                       [4.0, 0.0],    # on the line past the end
                       [0.5, 0.0]])   # on the segment
    assert point_segment_distance(points, s0, s1) == pytest.approx([3.0, 5.0, 2.0, 0.0])
    # A zero-length segment is its point.
    assert point_segment_distance(np.array([3.0, 4.0]), s0, s0) == pytest.approx(5.0)


def test_point_segment_distance_broadcasts_points_against_segments() -> None:
    starts = np.array([[0.0, 0.0], [0.0, 0.0]])
    ends = np.array([[1.0, 0.0], [0.0, 1.0]])
    points = np.array([[0.5, 2.0], [3.0, 0.5], [0.0, 0.0]])
    d = point_segment_distance(points[:, None, :], starts, ends)
    assert d.shape == (3, 2)
    np.testing.assert_allclose(d, [[2.0, np.hypot(0.5, 1.0)], [np.hypot(2.0, 0.5), 3.0],
                                   [0.0, 0.0]])


def test_nearest_segment_distance_and_scene_wall_distance_agree() -> None:
    points = np.array([[1.0, 0.5], [0.1, 0.5], [1.9, 0.95], [5.0, 0.5]])
    scene = Scene(SQUARE)
    starts, ends, _ = scene.wall_segments()
    expected = [0.5, 0.1, 0.05, 3.0]
    assert nearest_segment_distance(points, starts, ends) == pytest.approx(expected)
    assert scene.wall_distance(points) == pytest.approx(expected)
    assert np.all(np.isinf(nearest_segment_distance(points, starts[:0], ends[:0])))


def test_segments_cross_is_strict() -> None:
    a0, a1 = np.array([0.0, 0.0]), np.array([2.0, 2.0])
    assert segments_cross(a0, a1, np.array([0.0, 2.0]), np.array([2.0, 0.0]))  # an X
    assert not segments_cross(a0, a1, np.array([1.0, 1.0]), np.array([2.0, 0.0]))  # touches
    assert not segments_cross(a0, a1, np.array([3.0, 3.0]), np.array([4.0, 4.0]))  # collinear
    assert not segments_cross(a0, a1, np.array([3.0, 0.0]), np.array([4.0, 1.0]))  # apart


def test_segment_distance_hand_checked() -> None:
    a0 = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0]])
    a1 = np.array([[2.0, 0.0], [2.0, 0.0], [2.0, 2.0]])
    b0 = np.array([[0.0, 1.0], [3.0, 4.0], [0.0, 2.0]])
    b1 = np.array([[2.0, 1.5], [6.0, 4.0], [2.0, 0.0]])
    # 1 m above the first's start; end (2, 0) to end (3, 4); crossing segments are 0 apart.
    assert segment_distance(a0, a1, b0, b1) == pytest.approx([1.0, np.hypot(1.0, 4.0), 0.0])


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-5, 5), min_size=8, max_size=8))
def test_segment_distance_is_symmetric_and_bounded_by_end_points(values: list[float]) -> None:
    a0, a1, b0, b1 = (np.array(values[i:i + 2]) for i in range(0, 8, 2))
    d = float(segment_distance(a0, a1, b0, b1))
    assert d == pytest.approx(float(segment_distance(b0, b1, a0, a1)))
    assert d <= min(np.linalg.norm(p - q) for p in (a0, a1) for q in (b0, b1)) + 1e-12
    # Sampled points of both segments are never closer than the distance.
    t = np.linspace(0.0, 1.0, 21)[:, None]
    pa, pb = a0 + t * (a1 - a0), b0 + t * (b1 - b0)
    assert np.linalg.norm(pa[:, None] - pb[None], axis=2).min() >= d - 1e-9


def test_segments_blocked_counts_wall_end_points_but_not_sight_line_ends() -> None:
    wall_starts = np.array([[1.0, -1.0]])
    wall_ends = np.array([[1.0, 1.0]])
    p = np.array([[0.0, 0.0], [0.0, 1.0], [0.0, 0.0], [0.0, 2.0]])
    q = np.array([[2.0, 0.0], [2.0, 1.0], [1.0, 0.0], [2.0, 2.0]])
    # through the wall; through its end point; ending on it; passing above it
    np.testing.assert_array_equal(segments_blocked(p, q, wall_starts, wall_ends),
                                  [True, True, False, False])
    skip = np.array([0, -1, -1, -1])
    np.testing.assert_array_equal(segments_blocked(p, q, wall_starts, wall_ends, skip),
                                  [False, True, False, False])
