"""Geometric verification of classes on hand-made scenes with known points."""
from __future__ import annotations

import numpy as np
import pytest

from vbn_common.geometry.camera import PinholeCamera, make_camera
from visibility_builder.classes import ClassResult
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.verification import VerifyConfig, verify_classes

PANORAMA = make_camera('panoramic')


def observe(camera, pose: np.ndarray, point: np.ndarray) -> np.ndarray:
    """Pixel of a point (height relative to the camera) seen from a camera pose."""
    dx, dy = point[0] - pose[0], point[1] - pose[1]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    local = np.array([[-(-s * dx + c * dy), -point[2], c * dx + s * dy]])
    uv, valid = camera.project(local)
    assert valid.all()
    return uv[0]


def make_classes(labels: list[list[int]], n_classes: int) -> ClassResult:
    import scipy.sparse as sp
    rows = [v for v, lab in enumerate(labels) for c in lab if c >= 0]
    cols = [c for lab in labels for c in lab if c >= 0]
    vis = sp.csr_matrix((np.ones(len(rows), bool), (rows, cols)),
                        shape=(len(labels), n_classes))
    return ClassResult([np.array(lab, np.int64) for lab in labels], n_classes, vis, {})


def grid_poses(n: int = 4) -> np.ndarray:
    return np.array([(0.25 * i, 0.25 * j, 0.3 * i - 0.2 * j)
                     for i in range(n) for j in range(n)])


def test_pure_classes_pass_and_a_mixed_class_is_excluded():
    poses = grid_poses()                                  # 16 poses
    wall = np.array([[4.0, 1.0, 0.3], [4.0, -1.5, -0.2], [-3.0, 2.0, 0.5]])
    # class 0 and 1 pure; class 2 sees point 2 from half the poses and a point
    # 1 m away from the other half (a chain through repeated texture).
    twin = wall[2] + np.array([0.0, 1.0, 0.0])
    keypoints, labels = [], []
    for v, pose in enumerate(poses):
        third = wall[2] if v < 8 else twin
        keypoints.append(np.array([observe(PANORAMA, pose, wall[0]),
                                   observe(PANORAMA, pose, wall[1]),
                                   observe(PANORAMA, pose, third)]))
        labels.append([0, 1, 2])
    sizes = [np.full(3, 4.0)] * len(poses)
    result = verify_classes(make_classes(labels, 3), keypoints, sizes, list(poses), PANORAMA)
    assert result.n_classes == 2
    assert [lab.tolist() for lab in result.labels] == [[0, 1, -1]] * len(poses)
    assert result.visibility.shape == (16, 2) and result.visibility.sum() == 32
    assert result.stats['excluded_geometry'] == 1
    assert result.stats['verified'] == 3


def test_one_wrong_member_is_removed_and_the_class_kept():
    poses = grid_poses(5)                                 # 25 poses
    point = np.array([3.0, 2.0, 0.4])
    keypoints = [observe(PANORAMA, p, point)[None] for p in poses]
    keypoints[7] = keypoints[7] + np.array([[30.0, 0.0]])   # another point's keypoint
    labels = [[0]] * len(poses)
    sizes = [np.full(1, 4.0)] * len(poses)
    result = verify_classes(make_classes(labels, 1), keypoints, sizes, list(poses), PANORAMA)
    assert result.n_classes == 1
    assert [int(lab[0]) for lab in result.labels] == [0 if v != 7 else -1 for v in range(25)]
    assert result.stats['outlier_features'] == 1
    # with no outlier allowed the class goes
    strict = verify_classes(make_classes(labels, 1), keypoints, sizes, list(poses), PANORAMA,
                            VerifyConfig(max_outlier_fraction=0.0))
    assert strict.n_classes == 0 and strict.visibility.shape == (25, 0)


def test_tolerance_grows_with_keypoint_size():
    poses = grid_poses()
    point = np.array([2.0, -3.0, 0.0])
    keypoints = [observe(PANORAMA, p, point)[None] for p in poses]
    rng = np.random.default_rng(3)
    noisy = [k + rng.uniform(-6, 6, size=k.shape) for k in keypoints]
    labels = [[0]] * len(poses)
    small = verify_classes(make_classes(labels, 1), noisy, [np.full(1, 4.0)] * 16,
                           list(poses), PANORAMA, VerifyConfig(max_outlier_fraction=0.0))
    large = verify_classes(make_classes(labels, 1), noisy, [np.full(1, 60.0)] * 16,
                           list(poses), PANORAMA, VerifyConfig(max_outlier_fraction=0.0))
    assert small.n_classes == 0 and large.n_classes == 1


def test_pinhole_images_of_one_pose_have_their_own_headings():
    camera = PinholeCamera.from_fov(640, 480, 90.0)
    point = np.array([2.0, 0.5, 0.2])
    other = np.array([0.3, 3.0, 0.0])                       # ahead of the left cameras
    # two images per pose, forward and left; each point is seen in one of them
    keypoints, camera_poses, labels = [], [], []
    for x in (0.0, 0.25, 0.5):
        forward = np.array([x, 0.0, 0.0])
        left = np.array([x, 0.0, np.pi / 2])
        keypoints.append(np.array([observe(camera, forward, point),
                                   observe(camera, left, other)]))
        camera_poses.append(np.array([forward, left]))
        labels.append([0, 1])
    result = verify_classes(make_classes(labels, 2), keypoints, [np.full(2, 3.0)] * 3,
                            camera_poses, camera, VerifyConfig(max_outlier_fraction=0.0))
    assert result.n_classes == 2
    # the same keypoints credited to the wrong heading no longer agree
    swapped = [cp[::-1] for cp in camera_poses]
    bad = verify_classes(make_classes(labels, 2), keypoints, [np.full(2, 3.0)] * 3,
                         swapped, camera, VerifyConfig(max_outlier_fraction=0.0))
    assert bad.n_classes == 0


def test_disabled_and_single_member_classes_pass_unchanged():
    classes = make_classes([[0, 1], [0, -1]], 2)
    keypoints = [np.array([[10.0, 100.0], [500.0, 100.0]]), np.array([[900.0, 20.0],
                                                                      [3.0, 4.0]])]
    poses = [np.zeros(3), np.array([0.25, 0.0, 0.0])]
    sizes = [np.full(2, 4.0)] * 2
    off = verify_classes(classes, keypoints, sizes, poses, PANORAMA, VerifyConfig(enabled=False))
    assert off is classes
    on = verify_classes(classes, keypoints, sizes, poses, PANORAMA)
    # class 0's two rays do not meet (opposite directions); class 1 has one member
    assert on.n_classes == 1 and [lab.tolist() for lab in on.labels] == [[-1, 0], [-1, -1]]


@pytest.mark.parametrize('kwargs, message', [
    ({'tolerance_px': -1}, 'tolerance_px must be a non-negative number'),
    ({'size_fraction': float('nan')}, 'size_fraction must be a non-negative number'),
    ({'tolerance_px': 0, 'size_fraction': 0}, 'cannot both be 0'),
    ({'max_outlier_fraction': 1.5}, r'max_outlier_fraction must be in \[0, 1\]'),
])
def test_bad_config_is_one_clear_error(kwargs, message):
    with pytest.raises(VisibilityBuilderError, match=message):
        VerifyConfig(**kwargs)


def test_mismatched_inputs_are_clear_errors():
    classes = make_classes([[0, 1]], 2)
    with pytest.raises(VisibilityBuilderError, match='for each of the 1 poses'):
        verify_classes(classes, [], [], [], PANORAMA)
    with pytest.raises(VisibilityBuilderError, match='keypoints of pose 0 hold 1 features'):
        verify_classes(classes, [np.zeros((1, 2))], [np.zeros(2)], [np.zeros(3)], PANORAMA)
