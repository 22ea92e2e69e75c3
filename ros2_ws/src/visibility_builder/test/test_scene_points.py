"""The scene points' descriptor choice: chunked in float32, the same as all at once."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np

from visibility_builder.scene_points import central_members


def _naive(descriptors: np.ndarray, group: np.ndarray, n: int) -> np.ndarray:
    """Every group's mean in float64, then each member's distance: the old way."""
    chosen = np.full(n, -1)
    for g in range(n):
        rows = np.flatnonzero(group == g)
        if rows.size:
            mean = descriptors[rows].astype(float).mean(axis=0)
            dist = np.linalg.norm(descriptors[rows] - mean, axis=1)
            chosen[g] = rows[np.argmin(dist)]
    return chosen


def test_the_central_member_by_hand() -> None:
    # Group 0: 0, 4, 5 -> mean 3, nearest 4 (row 1); group 1: one member; group 2: none.
    descriptors = np.array([[0, 0], [4, 4], [5, 5], [9, 9]], np.uint8)
    np.testing.assert_array_equal(central_members(descriptors, np.array([0, 0, 0, 1]), 3),
                                  [1, 3, -1])


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1), st.integers(0, 300), st.integers(1, 40),
       st.integers(1, 64))
def test_chunks_give_the_same_choice_as_all_at_once(seed: int, m: int, n: int,
                                                    chunk: int) -> None:
    rng = np.random.default_rng(seed)
    descriptors = rng.integers(0, 256, (m, 16)).astype(np.uint8)
    group = rng.integers(0, n, m)
    got = central_members(descriptors, group, n, chunk=chunk)
    want = _naive(descriptors, group, n)
    for g in range(n):
        if want[g] < 0:
            assert got[g] == -1
            continue
        # Equal distances may pick another member; the distance must be the least.
        rows = group == g
        mean = descriptors[rows].astype(float).mean(axis=0)
        d_got = np.linalg.norm(descriptors[got[g]] - mean)
        d_want = np.linalg.norm(descriptors[want[g]] - mean)
        assert group[got[g]] == g and abs(d_got - d_want) < 1e-3


def test_a_point_seen_by_three_cameras_by_hand() -> None:
    from vbn_common.features import ImageFeatures
    from vbn_common.geometry.camera import make_camera
    from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
    from visibility_builder.scene_points import scene_points

    camera = make_camera('panoramic')
    point = np.array([2.0, 2.0, 0.3])
    poses = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    features, labels = [], []
    for pose in poses:
        optical = (point - [pose[0], pose[1], 0.0]) @ BASE_TO_CAMERA_ROTATION
        uv, ok = camera.project(optical[None])
        assert ok.all()
        features.append(ImageFeatures(uv.astype(np.float32), np.ones(1, np.float32),
                                      np.zeros(1, np.float32), np.ones(1, np.float32),
                                      np.full((1, 128), 7, np.uint8)))
        labels.append(np.array([0]))
    points = scene_points(labels, features, poses, camera, np.array([0]))
    assert points.n_points == 1 and points.views.tolist() == [3]
    np.testing.assert_allclose(points.xyz[0], point, atol=1e-3)
    # Seen from the centre of the three positions, the farthest sqrt(5)/3 from it.
    np.testing.assert_allclose(points.seen_from[0], [1 / 3, 1 / 3, math.sqrt(5) / 3],
                               atol=1e-12)
