from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from vbn_common.features import ImageFeatures
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.model_views import (
    ImageTable,
    ModelViewConfig,
    class_descriptors,
    extra_features,
    select_model_views,
)


def table_of(xy: np.ndarray, labels: list[list[int]]) -> ImageTable:
    """One image per pose at ``xy``; image i shows the classes ``labels[i]``."""
    feats = []
    for i, lab in enumerate(labels):
        n = len(lab)
        feats.append(ImageFeatures(
            keypoints=np.column_stack([np.arange(n), np.full(n, i)]).astype(np.float32),
            sizes=np.ones(n, np.float32), angles=np.zeros(n, np.float32),
            responses=np.ones(n, np.float32),
            descriptors=np.full((n, 128), i, np.uint8)))
    n = len(labels)
    return ImageTable(pose=np.arange(n), stamp_ns=np.arange(n) * 10,
                      camera_xy=np.asarray(xy, float), camera_yaw=np.zeros(n),
                      features=feats, labels=[np.asarray(lab, np.int64) for lab in labels])


def test_two_views_at_the_largest_baseline_and_a_third_off_their_line() -> None:
    # A 3 x 2 block of poses 1 m apart; every image shows the landmark {0, 1}.
    xy = np.array([[0, 0], [1, 0], [2, 0], [0, 1], [1, 1], [2, 1]], float)
    table = table_of(xy, [[0, 1, 5], [0, 1], [1, 0, 7], [0, 1], [0, 1], [0, 1, 5]])
    views = select_model_views(table, np.arange(6), np.array([0, 1]), np.array([5]))
    # Largest baseline: (0,0)-(2,1) or (0,1)-(2,0), sqrt(5); ties go to the pair whose
    # images show more extra classes: images 0 and 5 both show class 5.
    assert [v.pose for v in views[:2]] == [0, 5]
    # Third: farthest from the line through (0,0) and (2,1): (2,0) or (0,1), 0.894 m.
    assert len(views) == 3 and views[2].pose in (2, 3)
    first = views[0]
    assert sorted(first.class_ids.tolist()) == [0, 1, 5]  # landmark and extra it shows
    assert first.keypoints.shape == (3, 2) and first.descriptors.shape == (3, 128)
    assert (first.x, first.y, first.image_stamp_ns) == (0.0, 0.0, 0)


def test_a_strip_keeps_two_views_and_images_without_the_landmark_are_not_candidates() -> None:
    xy = np.array([[0, 0], [1, 0], [2, 0], [3, 0]], float)
    table = table_of(xy, [[0, 1], [0, 1], [0, 1], [0]])  # pose 3 lacks class 1
    views = select_model_views(table, np.arange(4), np.array([0, 1]), np.zeros(0, np.int64),
                               ModelViewConfig(min_third_offset=0.1))
    assert [v.pose for v in views] == [0, 2]  # collinear: no third view


def test_no_image_with_the_whole_landmark_is_an_error() -> None:
    table = table_of(np.array([[0, 0], [1, 0]], float), [[0], [1]])
    with pytest.raises(VisibilityBuilderError, match='shows all of its landmark'):
        select_model_views(table, np.arange(2), np.array([0, 1]), np.zeros(0, np.int64))


def test_extra_features_by_fraction_capped_and_never_landmark() -> None:
    visibility = sp.csr_matrix(np.array([
        [1, 1, 1, 1, 0],
        [1, 1, 1, 0, 0],
        [1, 1, 1, 1, 1],
        [1, 1, 0, 1, 0],
        [1, 1, 1, 1, 0],
    ], bool))
    poses = np.arange(5)
    got = extra_features(visibility, poses, np.array([0]),
                         ModelViewConfig(extra_min_fraction=0.8, max_extra=10))
    assert got.tolist() == [1, 2, 3]  # 5, 4, 4 of 5 poses; class 4 (1 of 5) is out
    capped = extra_features(visibility, poses, np.array([0]),
                            ModelViewConfig(extra_min_fraction=0.8, max_extra=2))
    assert capped.tolist() == [1, 2]


def test_class_descriptors_spread_over_the_poses() -> None:
    # Class 0 seen from x = 0, 1, 2, 3, 4 (descriptor value = x); class 1 from one place.
    classes = np.array([0, 0, 0, 0, 0, 1])
    positions = np.array([[0, 0], [1, 0], [2, 0], [3, 0], [4, 0], [9, 9]], float)
    descriptors = np.repeat(np.array([[0], [1], [2], [3], [4], [9]], np.uint8), 128, axis=1)
    rows, offsets = class_descriptors(classes, descriptors, positions, 2, per_class=3)
    assert offsets.tolist() == [0, 3, 4]
    # Nearest the centroid first (x = 2), then the farthest (x = 0), then x = 4.
    assert rows[:3, 0].tolist() == [2, 0, 4]
    assert rows[3, 0] == 9
