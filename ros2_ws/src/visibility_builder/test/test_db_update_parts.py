"""The pure parts of ``vbn db-update``: images to poses, blocked poses, labels, merges."""
from __future__ import annotations

import cv2
from database_samples import sample_database  # noqa: E402
import numpy as np
import pytest
import scipy.sparse as sp

from landmark_db.database import FeatureClasses, ScenePoints
from vbn_common.features import ImageFeatures
from vbn_common.geometry.camera import PinholeCamera
from visibility_builder.db_update import (
    UpdateConfig,
    assign_images,
    enclosed_poses,
    label_features,
    replace_visibility,
)
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.update_classes import NewClasses, merge_classes, merge_points


def test_images_go_to_the_pose_they_were_taken_at() -> None:
    db = sample_database(np.random.default_rng(0))            # 3 x 3 poses, 0.5 m apart
    xy = db.poses.xy
    at = np.array([xy[4] + [0.1, -0.1], xy[0], xy[8] + [0.3, 0.0], [50.0, 50.0]])
    poses = assign_images(db, at, np.zeros(len(at)), tolerance=0.5)
    assert poses.tolist() == [4, 0, -1, -1]                 # 0.3 m > half the spacing


def test_a_pose_surrounded_by_the_update_is_blocked() -> None:
    grid = np.array([(x, y) for y in range(5) for x in range(5)], float) * 0.25
    centre = 12                                             # (0.5, 0.5)
    around = np.setdiff1d(np.arange(25), [centre, 11, 13])  # a 3-pose cupboard
    blocked = enclosed_poses(grid, around, 0.6)
    assert blocked.tolist() == [11, 12, 13]
    # A partial re-exploration of the left half leaves the right half as it is.
    left = np.flatnonzero(grid[:, 0] <= 0.25)
    assert enclosed_poses(grid, left, 0.6).size == 0


def test_a_blocked_pose_leaves_the_pose_graph_and_no_neighbourhood_through_it() -> None:
    from landmark_db.decomposition import service

    db = sample_database(np.random.default_rng(0))            # 3 x 3 poses, 0.5 m apart
    n, m = db.n_poses, db.n_classes
    # Every pose sees every class but the centre, where a cupboard stands now.
    visibility = np.ones((n, m), bool)
    visibility[4] = False
    visibility = sp.csr_matrix(visibility)
    through = replace_visibility(db, visibility)
    around = replace_visibility(db, visibility, np.array([4]))
    assert through.adjacency[4].nnz == 4 and around.adjacency[4].nnz == 0
    assert around.adjacency.nnz == through.adjacency.nnz - 8   # its 4 edges, both ways
    # With rho 1, the centre's neighbours have nothing in common with it: through it,
    # only the corners are k-coverable; around it, all 8 poses the robot can stand on.
    assert service(through, [], k=2, rho=1).k_coverable == 4
    assert service(around, [], k=2, rho=1).k_coverable == 8


def _features(uv: np.ndarray, descriptors: np.ndarray) -> ImageFeatures:
    n = len(uv)
    zeros = np.zeros(n, np.float32)
    return ImageFeatures(keypoints=uv.astype(np.float32), sizes=zeros + 3, angles=zeros,
                         responses=zeros, descriptors=descriptors.astype(np.uint8))


def test_labels_need_the_right_place_as_well_as_the_right_look() -> None:
    rng = np.random.default_rng(1)
    camera = PinholeCamera.from_fov(640, 480, 90.0)
    # Three classes on a wall 2 m ahead of a camera at the origin looking along +x.
    points = np.array([[2.0, 0.5, 0.0], [2.0, -0.5, 0.2], [2.0, 0.0, -0.3]])
    looks = rng.integers(0, 120, (3, 128))
    classes = FeatureClasses(looks.astype(np.uint8), np.arange(4), sp.csr_matrix(
        np.ones((1, 3), bool)))
    from vbn_common.geometry.frames import world_points_to_camera

    uv, ok = camera.project(world_points_to_camera(np.zeros(3), 0.0, points))
    assert ok.all()
    # Feature 0: class 0 where it belongs; feature 1: class 1's look, 80 px from its place
    # (the poster hung elsewhere); feature 2: class 2 slightly re-imaged, 2 px off.
    near = np.clip(looks[2] + rng.integers(-3, 4, 128), 0, 255)
    frame = _features(np.array([uv[0], uv[1] + [80, 0], uv[2] + [2, 0]]),
                      np.array([looks[0], looks[1], near]))
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    matcher.add([classes.descriptors.astype(np.float32)])
    for visible in (np.ones(3, bool), np.zeros(3, bool)):     # guided and matched alike
        labels = label_features(frame, np.zeros(3), camera, UpdateConfig(), classes, matcher,
                                points, visible)
        assert labels.tolist() == [0, -1, 2]


def test_new_classes_are_appended_with_their_points() -> None:
    old = FeatureClasses(np.zeros((3, 128), np.uint8), np.array([0, 1, 3]),
                         sp.csr_matrix(np.array([[1, 0], [1, 1], [0, 1]], bool)))
    new = NewClasses(1, sp.csr_matrix(np.array([[1], [1]], bool)), [],
                     np.full((2, 128), 7, np.uint8), np.array([0, 2]),
                     ScenePoints(np.ones((2, 3)), np.array([0, -1]),
                                 np.zeros((2, 128), np.uint8), np.array([2, 2])))
    merged = merge_classes(old, old.visibility, new, np.array([1, 2]))
    assert merged.n_classes == 3 and merged.offsets.tolist() == [0, 1, 3, 5]
    assert merged.visibility.toarray().tolist() == [[True, False, False], [True, True, True],
                                                    [False, True, True]]
    points = merge_points(ScenePoints(np.zeros((1, 3)), np.array([1]),
                                      np.zeros((1, 128), np.uint8), np.array([3])),
                          new.points, 2)
    assert points.class_ids.tolist() == [1, 2, -1]   # a point of no class stays of none


def test_the_update_looks_at_the_points_its_images_show_from_where_they_were_seen() -> None:
    from landmark_db.database.points import SEEN_MARGIN_M
    from visibility_builder.update_classes import looked_at

    camera = PinholeCamera(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5)
    # Ahead of a camera at the origin facing +x, 2 m away: seen from around (0, 0).
    xyz = np.array([[2.0, 0.0, 0.0],     # seen from here: looked at
                    [2.0, 0.1, 0.1],     # seen from 3 m away (0.2 spread): SIFT's scale
                    [-2.0, 0.0, 0.0]])   # behind the camera
    seen = np.array([[0.1, 0.0, 0.2], [3.0, 0.0, 0.2], [0.0, 0.0, 0.2]])
    points = ScenePoints(xyz, np.full(3, -1), np.zeros((3, 128), np.uint8), np.full(3, 2),
                         seen_from=seen)
    origin = np.zeros((1, 3))
    assert looked_at(points, origin, camera).tolist() == [True, False, False]
    # Just beyond the spread plus the margin: not looked at.
    far = np.array([[-(0.2 + SEEN_MARGIN_M + 0.11), 0.0, 0.0]])
    assert not looked_at(points, far, camera)[0]
    # A file that does not say where its points were seen from: none looked at (a
    # panoramic image would show every point of the map).
    unknown = ScenePoints(xyz, np.full(3, -1), np.zeros((3, 128), np.uint8), np.full(3, 2))
    assert looked_at(unknown, origin, camera).tolist() == [False, False, False]
    assert looked_at(points, np.zeros((0, 3)), camera).tolist() == [False] * 3


def test_a_region_no_image_shows_is_drawn_again_with_what_the_images_show() -> None:
    from dataclasses import replace

    from visibility_builder.build_config import BuildConfig, DecompositionConfig
    from visibility_builder.model_views import ImageTable
    from visibility_builder.update_regions import new_regions

    db = sample_database(np.random.default_rng(0))            # 3 x 3 poses, 12 classes
    n, m = db.n_poses, db.n_classes
    # Every pose sees classes 0, 1 and 2 (0 first when the greedy steps tie), but the
    # only images there (poses 0 and 8) show 1 and 2: a region whose landmark holds 0
    # can have no model view.
    visibility = np.zeros((n, m), bool)
    visibility[:, :3] = True
    visibility = sp.csr_matrix(visibility)
    labels = [np.array([1, 2]), np.array([1, 2])]
    table = ImageTable(pose=np.array([0, 8]), stamp_ns=np.array([1, 2]),
                       camera_xy=db.poses.xy[[0, 8]], camera_yaw=np.zeros(2),
                       features=[_features(np.array([[10.0, 10.0], [20.0, 20.0]]),
                                           np.zeros((2, 128))) for _ in range(2)],
                       labels=labels)
    config = replace(BuildConfig(), decomposition=DecompositionConfig(
        algorithm='B2', k=2, rho=0, sigma=0))
    regions = new_regions(db, visibility, np.zeros(0, np.int64), np.arange(n), config,
                          table)
    assert len(regions) == 1 and sorted(regions[0].landmark.tolist()) == [1, 2]
    assert regions[0].poses.tolist() == list(range(n))
    assert [v.pose for v in regions[0].model_views] == [0, 8]
    # An image elsewhere that shows the whole landmark does not make the region's own
    # images show it: the features they lack are still hidden, and the region redrawn.
    elsewhere = replace(table, pose=np.array([0, 9 - 1]),
                        labels=[np.array([1, 2]), np.array([0, 1])])
    regions = new_regions(db, visibility, np.zeros(0, np.int64), np.array([0]), config,
                          replace(elsewhere, pose=np.array([0, 0])))
    assert [sorted(r.landmark.tolist()) for r in regions] == [[1, 2]]
    # Images that show only one class each: no landmark of 2 has a view.
    table = replace(table, labels=[np.array([1, -1]), np.array([2, -1])])
    with pytest.raises(VisibilityBuilderError, match='without a model view'):
        new_regions(db, visibility, np.zeros(0, np.int64), np.arange(n), config, table)
