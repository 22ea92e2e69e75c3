"""The scene points of a landmark database (database/points.py)."""
from __future__ import annotations

import numpy as np
import pytest

from landmark_db.database import ScenePoints
from landmark_db.errors import LandmarkDbError


def _points(ids, views=None) -> ScenePoints:
    n = len(ids)
    return ScenePoints(np.arange(3 * n, dtype=float).reshape(n, 3), np.asarray(ids),
                       np.zeros((n, 128), np.uint8),
                       np.full(n, 3) if views is None else np.asarray(views))


def test_class_points_put_each_point_at_its_class() -> None:
    points = _points([2, -1, 0])
    table = points.class_points(4)
    np.testing.assert_array_equal(table[2], [0, 1, 2])
    np.testing.assert_array_equal(table[0], [6, 7, 8])
    assert np.isnan(table[[1, 3]]).all()
    assert ScenePoints.empty().n_points == 0
    assert np.isnan(ScenePoints.empty().class_points(2)).all()


@pytest.mark.parametrize('ids, views, message', [
    ([1, 1], None, 'a class has two scene points'),
    ([-2], None, 'is not a class or -1'),
    ([0, 1], [3, 1], 'fewer than 2 views'),
])
def test_inconsistent_points_are_refused(ids, views, message) -> None:
    with pytest.raises(LandmarkDbError, match=message):
        _points(ids, views)


def test_descriptors_and_coordinates_are_checked() -> None:
    with pytest.raises(LandmarkDbError, match='2 scene point descriptors for 3 points'):
        ScenePoints(np.zeros((3, 3)), np.full(3, -1), np.zeros((2, 128)), np.full(3, 2))
    with pytest.raises(LandmarkDbError, match='non-finite'):
        ScenePoints(np.full((1, 3), np.nan), np.full(1, -1), np.zeros((1, 128)), np.full(1, 2))
    with pytest.raises(LandmarkDbError, match='out of range'):
        _points([5]).class_points(3)
