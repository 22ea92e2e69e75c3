"""The camera pose from the database's class points (absolute_pose.py)."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_localizer.absolute_pose import base_rays, hypotheses, refine_absolute, solve_absolute
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from vbn_common.geometry.mount import tilt_matrix

SIGMA = 0.5 / 300.0          # half a pixel at 300 px per radian
THRESHOLD = 3.0 / 300.0


def _points(rng: np.random.Generator, n: int = 80) -> np.ndarray:
    """Points on the walls of a 6 x 4 m room, between 1 m below and 1 m above the camera."""
    side = rng.integers(0, 4, n)
    t = rng.uniform(0, 1, n)
    x = np.where(side == 0, 0.0, np.where(side == 1, 6.0, 6.0 * t))
    y = np.where(side == 2, 0.0, np.where(side == 3, 4.0, 4.0 * t))
    return np.column_stack([x, y, rng.uniform(-1, 1, n)])


def _rays(points: np.ndarray, pose: np.ndarray, dz: float = 0.0,
          tilt: np.ndarray | None = None) -> np.ndarray:
    """Unit rays in the camera's level base frame (optionally tilted in the optical frame)."""
    d = points - np.r_[pose[:2], dz]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    base = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    if tilt is not None:
        optical = (base @ BASE_TO_CAMERA_ROTATION) @ tilt
        return base_rays(optical)
    return base / np.linalg.norm(base, axis=1, keepdims=True)


def test_three_points_fix_the_pose_by_hand() -> None:
    # The camera at the origin looking along +x: points ahead, left and behind-right.
    points = np.array([[2.0, 0.0, 0.3], [0.0, 1.0, -0.1], [-1.0, -1.0, 0.2]])
    rays = _rays(points, np.zeros(3))
    np.testing.assert_allclose(hypotheses(rays, points, np.array([[0, 1, 2]])),
                               [[0.0, 0.0, 0.0]], atol=1e-12)


@settings(max_examples=40, derandomize=True, deadline=None)
@given(x=st.floats(1.0, 5.0), y=st.floats(1.0, 3.0), yaw=st.floats(-math.pi, math.pi),
       seed=st.integers(0, 1000))
def test_hypotheses_recover_any_pose_from_exact_rays(x, y, yaw, seed) -> None:
    rng = np.random.default_rng(seed)
    points = _points(rng, 12)
    truth = np.array([x, y, yaw])
    found = hypotheses(_rays(points, truth), points,
                       np.array([rng.choice(12, 3, replace=False) for _ in range(5)]))
    good = np.all(np.isfinite(found), axis=1)
    assert good.any()
    np.testing.assert_allclose(found[good, :2], np.tile(truth[:2], (good.sum(), 1)), atol=1e-6)
    turn = (found[good, 2] - yaw + math.pi) % (2 * math.pi) - math.pi
    np.testing.assert_allclose(turn, 0.0, atol=1e-6)


def test_robust_pose_through_outliers_noise_tilt_and_height() -> None:
    rng = np.random.default_rng(3)
    points = _points(rng, 120)
    truth = np.array([2.2, 1.4, 0.7])
    tilt = tilt_matrix(0.6, -0.4)
    rays = _rays(points, truth, dz=0.04, tilt=tilt)
    rays = rays + rng.normal(0, SIGMA, rays.shape)
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    wrong = rng.choice(120, 60, replace=False)                 # half the matches wrong
    rays[wrong] = _rays(rng.permutation(points)[:60], truth)
    found = solve_absolute(rays, points, np.random.default_rng(0), threshold=THRESHOLD,
                           sigma=SIGMA, min_inliers=15, min_spread=math.radians(20),
                           tilt_prior=math.radians(1.0), height_prior=0.1)
    assert found is not None
    assert np.hypot(*(found.pose[:2] - truth[:2])) < 0.01
    assert abs(found.pose[2] - truth[2]) < math.radians(0.1)
    assert abs(found.tilt[2] - 0.04) < 0.01                     # the height offset
    assert math.hypot(*np.degrees(found.tilt[:2])) > 0.5         # the frame's tilt found
    assert found.n_inliers >= 55 and found.inliers[wrong].sum() <= 3
    std = np.sqrt(np.diag(found.covariance))
    assert 1e-4 < std[0] < 0.02 and 1e-4 < std[1] < 0.02


def test_level_camera_without_priors_recovers_the_planar_pose() -> None:
    rng = np.random.default_rng(4)
    points = _points(rng, 40)
    truth = np.array([3.0, 2.0, -2.0])
    found = solve_absolute(_rays(points, truth), points, np.random.default_rng(1),
                           threshold=THRESHOLD, sigma=SIGMA, min_inliers=10,
                           min_spread=0.3)
    assert found is not None
    np.testing.assert_allclose(found.pose, truth, atol=1e-6)
    np.testing.assert_allclose(found.tilt, 0.0)


def test_a_narrow_patch_of_points_or_too_few_inliers_is_refused() -> None:
    rng = np.random.default_rng(5)
    truth = np.array([1.0, 2.0, 0.0])
    patch = np.column_stack([np.full(30, 6.0), rng.uniform(1.9, 2.1, 30),
                             rng.uniform(-0.1, 0.1, 30)])   # 2 degrees wide
    kwargs = dict(threshold=THRESHOLD, sigma=SIGMA, min_spread=math.radians(20))
    assert solve_absolute(_rays(patch, truth), patch, np.random.default_rng(0),
                          min_inliers=10, **kwargs) is None
    points = _points(rng, 12)
    assert solve_absolute(_rays(points, truth), points, np.random.default_rng(0),
                          min_inliers=15, **kwargs) is None


def test_the_prior_pose_bounds_the_answer() -> None:
    rng = np.random.default_rng(6)
    points = _points(rng, 40)
    truth = np.array([3.0, 2.0, 0.5])
    kwargs = dict(threshold=THRESHOLD, sigma=SIGMA, min_inliers=10, min_spread=0.3)
    near = solve_absolute(_rays(points, truth), points, np.random.default_rng(0),
                          prior_pose=truth + [0.3, 0, 0], max_distance=0.75, **kwargs)
    assert near is not None and np.hypot(*(near.pose[:2] - truth[:2])) < 1e-6
    far = solve_absolute(_rays(points, truth), points, np.random.default_rng(0),
                         prior_pose=truth + [2.0, 0, 0], max_distance=0.75, **kwargs)
    assert far is None


def test_point_weights_leave_exact_rays_exact_and_trust_the_better_source() -> None:
    """Half the points measured 4 times worse: weights 1/16 on them halve the error (std).

    Exact rays give the truth whatever the weights. Over 20 noisy draws (half the rays
    at 0.5 px, half at 2 px), weighting each ray by the inverse of its variance gives a
    smaller mean squared position error than equal weights (the least-squares optimum),
    and the covariance's noise is then the weighted RMS error, near the better rays'.
    """
    rng = np.random.default_rng(11)
    points = _points(rng, 60)
    truth = np.array([2.5, 1.8, 0.3])
    start = truth + [0.05, -0.04, 0.02]
    weights = np.r_[np.full(30, 1.0 / 16.0), np.ones(30)]
    args = (THRESHOLD * 10, SIGMA, 0.0, 0.0)
    exact = refine_absolute(start, _rays(points, truth), points, *args,
                            point_weights=rng.uniform(0.1, 2.0, 60))
    np.testing.assert_allclose(exact[0][:3], truth, atol=1e-7)
    equal, weighted, stds = [], [], []
    for _ in range(20):
        noise = np.r_[np.full(30, 4.0 * SIGMA), np.full(30, SIGMA)][:, None]
        rays = _rays(points, truth) + rng.normal(0, 1, (60, 3)) * noise
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        a = refine_absolute(start, rays, points, *args)
        b = refine_absolute(start, rays, points, *args, point_weights=weights)
        equal.append(np.sum((a[0][:2] - truth[:2]) ** 2))
        weighted.append(np.sum((b[0][:2] - truth[:2]) ** 2))
        stds.append(np.sqrt(b[1][0, 0] / a[1][0, 0]))
    assert np.mean(weighted) < 0.4 * np.mean(equal)   # 0.25 here
    assert np.median(stds) < 0.7   # 0.5: the weighted pose claims less spread, as it has


# -- against a database index (test_support/localizer_samples.py) ---------------------

def _world():
    from localizer_samples import synthetic_database, wall_points

    from landmark_localizer.index import DatabaseIndex

    rng = np.random.default_rng(3)
    points = wall_points(rng, 90)
    return points, DatabaseIndex(synthetic_database(rng, points))


def _frame(points: np.ndarray, pose: np.ndarray, rng: np.random.Generator, wrong: int = 0):
    """The frame's features at the classes' pixels and 'nearest classes' matching them."""
    from localizer_samples import project

    from vbn_common.features import ImageFeatures

    uv, ok = project(pose, points)
    ids = np.flatnonzero(ok)
    uv = uv[ids] + rng.normal(0, 0.3, (len(ids), 2))
    classes = ids.copy()
    classes[rng.choice(len(ids), wrong, replace=False)] = rng.integers(0, len(points), wrong)
    n = len(ids)
    features = ImageFeatures(keypoints=uv.astype(np.float32), sizes=np.ones(n, np.float32),
                             angles=np.zeros(n, np.float32), responses=np.ones(n, np.float32),
                             descriptors=np.zeros((n, 128), np.float32))
    return features, (classes.astype(np.int64), np.full(n, 50.0), np.full(n, np.inf)), ids, uv


def test_absolute_solution_poses_a_frame_from_the_index_points() -> None:
    from landmark_localizer.absolute_pose import absolute_solution
    from landmark_localizer.config import LocalizerConfig

    points, index = _world()
    truth = np.array([2.3, 1.2, 0.9])
    rng = np.random.default_rng(7)
    features, nearest, _, _ = _frame(points, truth, rng, wrong=15)
    config = LocalizerConfig()
    found = absolute_solution(index, features, nearest, config, np.random.default_rng(0))
    assert found is not None and found.views_used == 0
    assert np.hypot(*(found.estimate.pose[:2] - truth[:2])) < 0.01
    assert abs(found.estimate.pose[2] - truth[2]) < math.radians(0.1)
    assert found.inliers >= 2 * config.absolute_min_inliers
    # Off: nothing; a prior two metres away: nothing either.
    assert absolute_solution(index, features, nearest,
                             LocalizerConfig(absolute_min_inliers=0), np.random.default_rng(0)) \
        is None
    assert absolute_solution(index, features, nearest, config, np.random.default_rng(0),
                             truth + [2.0, 0.0, 0.0]) is None


def test_the_odometrys_narrow_prediction_lets_fewer_inliers_pose_a_changed_view() -> None:
    from landmark_localizer.absolute_pose import absolute_solution
    from landmark_localizer.config import LocalizerConfig

    points, index = _world()
    truth = np.array([2.3, 1.2, 0.9])
    rng = np.random.default_rng(11)
    features, (classes, d1, d2), _, _ = _frame(points, truth, rng)
    # Posters rehung: all but 10 of the frame's matches point at the wrong class.
    keep = rng.choice(len(classes), 10, replace=False)
    wrong = np.setdiff1d(np.arange(len(classes)), keep)
    classes = classes.copy()
    classes[wrong] = (classes[wrong] + rng.integers(1, len(points), wrong.size)) % len(points)
    d1 = d1.copy()
    d1[wrong] += 10.0   # a right match is the nearer one where two share a class
    nearest = (classes, d1, d2)
    config = LocalizerConfig()
    go = np.random.default_rng(0)
    assert absolute_solution(index, features, nearest, config, go) is None
    assert absolute_solution(index, features, nearest, config, go, truth) is None  # 15
    predicted = truth + np.array([0.02, -0.01, 0.005])   # the bridge, a few cm wide
    found = absolute_solution(index, features, nearest, config, go, predicted,
                              min_inliers=8, max_distance=0.1, max_turn=0.02)
    assert found is not None and found.inliers >= 8
    assert np.hypot(*(found.estimate.pose[:2] - truth[:2])) < 0.01
    # A prediction 30 cm away with the same 10 cm window finds nothing there.
    assert absolute_solution(index, features, nearest, config, go,
                             truth + np.array([0.3, 0.0, 0.0]), min_inliers=8,
                             max_distance=0.1, max_turn=0.02) is None


def test_tracked_points_polish_a_close_seed_and_reject_a_wrong_one() -> None:
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    points, index = _world()
    truth = np.array([2.0, 1.4, -0.3])
    _, _, ids, uv = _frame(points, truth, np.random.default_rng(8))

    def seed(pose):
        estimate = PoseEstimate(*pose, np.eye(3) * 1e-4, 0.5, 0.0, 2, True)
        return PoseSolution(estimate, ids, 2, len(ids), 0.3)

    config = LocalizerConfig()
    close = refine_on_points(index, ids, uv, seed(truth + [0.03, -0.02, 0.01]), config)
    assert close is not None and np.hypot(*(close.estimate.pose[:2] - truth[:2])) < 0.005
    np.testing.assert_array_equal(close.inlier_classes, ids)
    assert refine_on_points(index, ids, uv, seed(truth + [0.4, 0.2, 0.1]), config) is None
    few = seed(truth + [0.4, 0.2, 0.1])
    assert refine_on_points(index, ids[:4], uv[:4], few, config) is few  # nothing to judge by


def test_the_odometry_carries_the_last_pose_through_a_turn_on_the_spot() -> None:
    from landmark_localizer.switching import MotionPredictor

    predictor = MotionPredictor()
    assert predictor.by_odometry(np.zeros(3)) is None            # no pose yet
    predictor.add(0, np.array([2.0, 1.0, math.pi / 2]), np.array([10.0, 5.0, 0.0]))
    # Odometry: 0.5 m ahead, then a quarter turn left, in its own frame.
    now = predictor.by_odometry(np.array([10.5, 5.0, math.pi / 2]))
    np.testing.assert_allclose(now[:2], [2.0, 1.5], atol=1e-12)
    assert abs(math.remainder(now[2] - math.pi, 2 * math.pi)) < 1e-12
    assert predictor.velocity() is None                           # one pose: no velocity
    assert predictor.by_odometry(None) is None
    predictor.add(10**8, np.array([2.0, 1.5, 3.0]), None)         # a pose without odometry
    assert predictor.by_odometry(np.array([10.5, 5.0, 0.0])) is None


def test_two_poses_that_fit_as_well_are_ambiguous_and_the_stronger_one_wins() -> None:
    rng = np.random.default_rng(9)
    a, b = _points(rng, 40), _points(rng, 40)
    pose_a, pose_b = np.array([2.0, 1.5, 0.3]), np.array([3.5, 2.5, 0.3])  # 1.8 m apart
    kwargs = dict(threshold=THRESHOLD, sigma=SIGMA, min_inliers=10, min_spread=0.3)
    # Half the matches fit one pose, half the other, as well: no pose.
    rays = np.vstack([_rays(a, pose_a), _rays(b, pose_b)])
    assert solve_absolute(rays, np.vstack([a, b]), np.random.default_rng(0), **kwargs) is None
    # 40 against 12: the 40.
    rays = np.vstack([_rays(a, pose_a), _rays(b[:12], pose_b)])
    found = solve_absolute(rays, np.vstack([a, b[:12]]), np.random.default_rng(0), **kwargs)
    assert found is not None and np.hypot(*(found.pose[:2] - pose_a[:2])) < 1e-6
    assert found.n_inliers == 40


def test_a_few_inliers_among_many_matches_are_still_found() -> None:
    # 20 right among 100 (a sample of three inliers 1 in 125): the adaptive batches.
    rng = np.random.default_rng(10)
    points = _points(rng, 100)
    truth = np.array([2.5, 2.0, -1.0])
    rays = _rays(rng.permutation(points), truth)
    rays[:20] = _rays(points[:20], truth)
    found = solve_absolute(rays, points, np.random.default_rng(0), threshold=THRESHOLD,
                           sigma=SIGMA, min_inliers=15, min_spread=0.3)
    # (a wrong match that falls within the threshold by chance pulls a little)
    assert found is not None and np.hypot(*(found.pose[:2] - truth[:2])) < 1e-3
    assert found.inliers[:20].all()


def test_absolute_solution_matches_the_scene_points_of_dropped_classes() -> None:
    from dataclasses import replace

    from localizer_samples import HEIGHT, synthetic_database, wall_points

    from landmark_db.database import ScenePoints
    from landmark_localizer.absolute_pose import absolute_solution
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.index import DatabaseIndex

    rng = np.random.default_rng(11)
    classes = wall_points(rng, 20)
    database = synthetic_database(rng, classes)
    # 60 points of no class (the filters dropped them) and the 20 classes' own.
    extra = wall_points(rng, 60)
    xyz = np.vstack([classes, extra])
    descriptors = rng.integers(0, 256, (80, 128)).astype(np.uint8)
    ids = np.r_[np.arange(20), np.full(60, -1)]
    relative = xyz - [0.0, 0.0, HEIGHT]        # scene points: z from the camera height
    index = DatabaseIndex(replace(database, points=ScenePoints(relative, ids, descriptors,
                                                               np.full(80, 3))))
    truth = np.array([2.3, 1.2, 0.9])
    _, _, seen, uv = _frame(xyz, truth, np.random.default_rng(12))
    from vbn_common.features import ImageFeatures

    n = len(seen)
    features = ImageFeatures(keypoints=uv.astype(np.float32), sizes=np.ones(n, np.float32),
                             angles=np.zeros(n, np.float32), responses=np.ones(n, np.float32),
                             descriptors=descriptors[seen].astype(np.float32))
    scene = index.nearest_scene_points(features.descriptors)
    np.testing.assert_array_equal(scene[0], seen)           # each descriptor its own point
    no_classes = (np.full(n, -1), np.full(n, np.inf), np.full(n, np.inf))
    config = LocalizerConfig()
    assert absolute_solution(index, features, no_classes, config,
                             np.random.default_rng(0)) is None
    found = absolute_solution(index, features, no_classes, config, np.random.default_rng(0),
                              scene=scene)
    assert found is not None and np.hypot(*(found.estimate.pose[:2] - truth[:2])) < 0.01
    # Its classes: those of the inlier points that have one.
    assert set(found.inlier_classes.tolist()) <= set(range(20))
    assert found.inliers > len(found.inlier_classes)


def test_the_motion_prior_holds_a_pose_the_points_leave_loose() -> None:
    """Exact rays give the truth with or without the prior; a patch of points on one
    far wall leaves the range loose, and the prior then holds it near the prediction."""
    rng = np.random.default_rng(6)
    points = _points(rng, 40)
    truth = np.array([3.0, 2.0, 0.4])
    args = (THRESHOLD, SIGMA, 0.0, 0.0)
    prior = (truth + np.array([0.01, -0.01, 0.002]), np.array([0.02, 0.02, 0.02]))
    exact = refine_absolute(truth + np.array([0.05, 0.05, 0.01]), _rays(points, truth),
                            points, *args, motion_prior=prior)
    assert exact is not None
    np.testing.assert_allclose(exact[0][:3], truth, atol=1e-4)  # 40 exact rays outweigh it
    # Four points close together on the wall x = 6 with 2 px of noise: without the prior
    # the range along x wanders; with a 1 cm prior at the truth it stays within 2 cm.
    wall = np.column_stack([np.full(4, 6.0), 2.0 + 0.05 * np.arange(4), 0.1 * np.arange(4)])
    noisy = _rays(wall, truth) + rng.normal(0, 2 * SIGMA * 2, (4, 3))
    noisy /= np.linalg.norm(noisy, axis=1, keepdims=True)
    start = truth + np.array([0.03, 0.0, 0.0])
    loose = refine_absolute(start, noisy, wall, *args)
    held = refine_absolute(start, noisy, wall, *args,
                           motion_prior=(truth, np.array([0.01, 0.01, 0.005])))
    assert held is not None
    assert np.hypot(*(held[0][:2] - truth[:2])) < 0.02
    assert loose is None or np.hypot(*(loose[0][:2] - truth[:2])) > 0.05
    # The prior's information enters the covariance: it is no wider than without it.
    if loose is not None:
        assert np.trace(held[1][:2, :2]) <= np.trace(loose[1][:2, :2])


def test_points_in_a_narrow_cone_polish_the_seed_only_with_the_motion_prior() -> None:
    """Points 7 degrees across fix the bearing; the motion prior fixes the rest.

    A two-view seed 20 cm off stays as it is without a prior (the points alone cannot
    judge it); with the prior 1 cm from the truth, points and prior put it within 1 cm.
    """
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    rng = np.random.default_rng(11)
    n = 40
    # A patch on the wall x = 6 seen from (2, 1.5): 0.5 m wide at 4 m is 7 degrees.
    points = np.column_stack([np.full(n, 6.0), rng.uniform(1.25, 1.75, n),
                              rng.uniform(0.6, 2.0, n)])
    from localizer_samples import project, synthetic_database

    from landmark_localizer.index import DatabaseIndex

    index = DatabaseIndex(synthetic_database(rng, points))
    truth = np.array([2.0, 1.5, 0.05])
    uv, ok = project(truth, points)
    ids = np.flatnonzero(ok)
    assert len(ids) == n
    uv = uv[ids] + rng.normal(0, 0.2, (n, 2))
    wrong = truth + [0.2, 0.02, 0.0]   # along the line of sight: the points barely object
    estimate = PoseEstimate(*wrong, np.eye(3) * 1e-4, 0.5, 0.0, 2, True)
    seed = PoseSolution(estimate, ids, 2, n, 0.3)
    config = LocalizerConfig()
    assert refine_on_points(index, ids, uv, seed, config) is seed
    prior = (truth + [0.01, 0.0, 0.0], np.array([0.02, 0.02, math.radians(1.0)]))
    found = refine_on_points(index, ids, uv, seed, config, motion_prior=prior)
    assert found is not None and found is not seed
    assert np.hypot(*(found.estimate.pose[:2] - truth[:2])) < 0.01


def test_residuals_are_judged_at_the_coarser_cameras_pixels() -> None:
    """A run camera of twice the database's resolution: the database's pixels count."""
    from localizer_samples import CAMERA

    from vbn_common.geometry.camera import PanoramicCamera, pixels_per_radian

    _, index = _world()
    assert index.residual_focal == pytest.approx(pixels_per_radian(CAMERA))
    index.frame_camera = PanoramicCamera(2 * CAMERA.width, 2 * CAMERA.height)
    assert index.residual_focal == pytest.approx(pixels_per_radian(CAMERA))
    index.frame_camera = PanoramicCamera(CAMERA.width // 2, CAMERA.height // 2)
    assert index.residual_focal == pytest.approx(pixels_per_radian(CAMERA) / 2)


def test_a_finer_run_camera_is_judged_at_the_database_pixels() -> None:
    """A run camera of twice the database's resolution, with the database's noise.

    Every keypoint 2 database pixels left or right (4 of the run camera's, which no planar
    pose explains): judged at the run camera's pixels (3 px) every point would be an
    outlier and the seed would stay; at the coarser camera's
    (:attr:`DatabaseIndex.residual_focal`) they are inliers and polish it.
    """
    from localizer_samples import CAMERA, HEIGHT

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.camera import PanoramicCamera
    from vbn_common.geometry.frames import world_points_to_camera
    from vbn_common.geometry.localize import PoseEstimate

    points, index = _world()
    fine = PanoramicCamera(2 * CAMERA.width, 2 * CAMERA.height)
    index.frame_camera = fine
    truth = np.array([2.0, 1.4, -0.3])
    uv, ok = fine.project(world_points_to_camera(truth, HEIGHT, points))
    ids = np.flatnonzero(ok)
    signs = np.random.default_rng(9).choice([-1.0, 1.0], len(ids))
    uv = uv[ids] + np.column_stack([4.0 * signs, np.zeros(len(ids))])
    seed = PoseSolution(PoseEstimate(*(truth + [0.03, -0.02, 0.005]), np.eye(3) * 1e-4,
                                     0.5, 0.0, 2, True), ids, 2, len(ids), 0.3)
    found = refine_on_points(index, ids, uv, seed, LocalizerConfig())
    assert found is not None and found is not seed
    assert np.hypot(*(found.estimate.pose[:2] - truth[:2])) < 0.01
    # The two-view seed is kept beside the refined pose (vbn localize reports both).
    np.testing.assert_array_equal(found.two_view_pose, seed.estimate.pose)
    np.testing.assert_array_equal(seed.two_view_pose, seed.estimate.pose)
    assert PoseSolution(seed.estimate, ids, 0, len(ids), 0.0).two_view_pose is None


def test_scene_points_join_the_refinement_but_never_judge_the_seed() -> None:
    """The narrow patch above (7 degrees), now with exact scene points all around.

    They never judge the seed: without a motion prior the patch cannot refuse the 20 cm
    seed and the seed stands (the scene points are measured where the seed puts them, so
    they would confirm it), and a seed the patch rejects is still rejected. With the
    motion prior they join the final refinement and put the pose within 2 mm; a scene
    measurement 10 px off is left out (the pose is as good)."""
    from localizer_samples import HEIGHT, project, synthetic_database, wall_points

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.index import DatabaseIndex
    from landmark_localizer.points_refinement import refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    rng = np.random.default_rng(11)
    n = 40
    points = np.column_stack([np.full(n, 6.0), rng.uniform(1.25, 1.75, n),
                              rng.uniform(0.6, 2.0, n)])
    index = DatabaseIndex(synthetic_database(rng, points))
    truth = np.array([2.0, 1.5, 0.05])
    uv, ok = project(truth, points)
    ids = np.flatnonzero(ok)
    uv = uv[ids] + rng.normal(0, 0.2, (n, 2))
    wrong = truth + [0.2, 0.02, 0.0]
    seed = PoseSolution(PoseEstimate(*wrong, np.eye(3) * 1e-4, 0.5, 0.0, 2, True), ids, 2,
                        n, 0.3)
    config = LocalizerConfig()
    around = wall_points(np.random.default_rng(3), 60)
    scene_uv, seen = project(truth, around)
    xyz = around[seen] - [0.0, 0.0, HEIGHT]              # scene points: z from the camera
    assert refine_on_points(index, ids, uv, seed, config,
                            scene=(scene_uv[seen], xyz)) is seed
    # The prior holds the range (1 cm off, 2 cm wide); the scene points polish the rest.
    prior = (truth + [0.01, 0.0, 0.0], np.array([0.02, 0.02, math.radians(1.0)]))
    alone = refine_on_points(index, ids, uv, seed, config, motion_prior=prior)
    found = refine_on_points(index, ids, uv, seed, config, motion_prior=prior,
                             scene=(scene_uv[seen], xyz))
    assert found is not None and found is not seed
    assert np.hypot(*(found.estimate.pose[:2] - truth[:2])) < 0.002
    assert np.hypot(*(found.estimate.pose[:2] - truth[:2])) < \
        np.hypot(*(alone.estimate.pose[:2] - truth[:2]))
    assert found.tilt is not None and np.abs(found.tilt).max() < 1e-3
    off = scene_uv[seen].copy()
    off[0] += [10.0, 0.0]
    again = refine_on_points(index, ids, uv, seed, config, motion_prior=prior,
                             scene=(off, xyz))
    assert np.hypot(*(again.estimate.pose[:2] - truth[:2])) < 0.002
    far = PoseSolution(PoseEstimate(*(truth + [0.0, 0.6, 0.3]), np.eye(3) * 1e-4, 0.5, 0.0,
                                    2, True), ids, 2, n, 0.3)
    assert refine_on_points(index, ids, uv, far, config, scene=(scene_uv[seen], xyz)) is None


def test_a_small_huber_threshold_sets_aside_measurements_a_pixel_or_two_off() -> None:
    """Scene points with 0.1 px noise, an eighth of them 1.5 to 2.5 px off one way (within
    the 3 px inlier threshold, so none is dropped): least squares (a 3 px Huber) is
    pulled (the heading most: the outliers all lean one way); the default 0.3 px
    threshold keeps the pose within a millimetre and the heading within 0.01 deg. Exact
    measurements give the pose within half a millimetre either way."""
    from localizer_samples import HEIGHT, project, wall_points

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    points, index = _world()
    truth = np.array([2.0, 1.4, -0.3])
    rng = np.random.default_rng(21)
    _, _, ids, uv = _frame(points, truth, rng)
    around = wall_points(np.random.default_rng(4), 120)
    scene_uv, seen = project(truth, around)
    xyz = around[seen] - [0.0, 0.0, HEIGHT]
    exact = scene_uv[seen]
    noisy = exact + rng.normal(0, 0.1, exact.shape)
    bad = rng.choice(len(noisy), len(noisy) // 8, replace=False)
    noisy[bad] += np.column_stack([rng.uniform(1.5, 2.5, len(bad)), np.zeros(len(bad))])
    seed = PoseSolution(PoseEstimate(*(truth + [0.02, -0.01, 0.005]), np.eye(3) * 1e-4, 0.5,
                                     0.0, 2, True), ids, 2, len(ids), 0.3)

    def error(scene_uv, huber):
        found = refine_on_points(index, ids, uv, seed, LocalizerConfig(absolute_huber_px=huber),
                                 scene=(scene_uv, xyz))
        assert found is not None and found is not seed
        return (np.hypot(*(found.estimate.pose[:2] - truth[:2])),
                abs(math.degrees(found.estimate.pose[2] - truth[2])))

    assert LocalizerConfig().absolute_huber_px == 0.3
    small, wide = error(noisy, 0.3), error(noisy, 3.0)
    assert small[0] < 0.001 and small[1] < 0.01
    assert wide[1] > 4 * small[1] and wide[0] > small[0]   # 0.047 against 0.008 deg
    # The class tracks (0.3 px noise) alone hold the exact scene points within 0.5 mm.
    assert error(exact, 0.3)[0] < 0.0005 and error(exact, 3.0)[0] < 0.0005
    with pytest.raises(Exception, match='absolute_huber_px'):
        LocalizerConfig(absolute_huber_px=0.0)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10**6))
def test_the_closed_form_jacobian_is_the_residuals_derivative(seed: int) -> None:
    from landmark_localizer.absolute_pose import _residuals
    from landmark_localizer.angular_kernels import linearise

    rng = np.random.default_rng(seed)
    points = rng.uniform(-3, 3, (12, 3))
    rays = rng.normal(size=(12, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    state = np.r_[rng.uniform(-1, 1, 2), rng.uniform(-np.pi, np.pi),
                  rng.uniform(-0.1, 0.1, 2), rng.uniform(-0.2, 0.2)]
    r, jac = linearise(state, rays, points)
    np.testing.assert_allclose(r, _residuals(state, rays, points), atol=1e-12)
    for k in range(6):
        step = np.zeros(6)
        step[k] = 1e-6
        numeric = (_residuals(state + step, rays, points)
                   - _residuals(state - step, rays, points)) / 2e-6
        np.testing.assert_allclose(jac[:, :, k], numeric, atol=1e-6)


def test_points_measured_by_their_patches_join_the_matches_near_a_prediction() -> None:
    from dataclasses import replace

    from localizer_samples import HEIGHT, synthetic_database, wall_points

    from landmark_db.database import ScenePoints
    from landmark_localizer.absolute_pose import absolute_solution
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.index import DatabaseIndex
    from vbn_common.features import ImageFeatures

    rng = np.random.default_rng(21)
    xyz = wall_points(rng, 80)
    database = synthetic_database(rng, wall_points(rng, 20))
    descriptors = rng.integers(0, 256, (80, 128)).astype(np.uint8)
    index = DatabaseIndex(replace(database, points=ScenePoints(
        xyz - [0.0, 0.0, HEIGHT], np.full(80, -1), descriptors, np.full(80, 3))))
    truth = np.array([2.3, 1.2, 0.9])
    _, _, seen, uv = _frame(xyz, truth, np.random.default_rng(22))
    # The frame's SIFT matches: 4 right ones (a changed stretch); the patches measured
    # where the prediction puts 20 others (to 0.05 px), 3 of them 3 px off.
    sift = seen[:4]
    features = ImageFeatures(keypoints=uv[:4].astype(np.float32), sizes=np.ones(4, np.float32),
                             angles=np.zeros(4, np.float32), responses=np.ones(4, np.float32),
                             descriptors=descriptors[sift].astype(np.float32))
    scene = (sift.astype(np.int64), np.full(4, 50.0), np.full(4, np.inf))
    no_classes = (np.full(4, -1), np.full(4, np.inf), np.full(4, np.inf))
    from localizer_samples import project

    rows = seen[4:24]
    measured_uv, _ = project(truth, xyz[rows])
    measured_uv = measured_uv + np.random.default_rng(23).normal(0, 0.05, measured_uv.shape)
    measured_uv[:3, 0] += 3.0
    config = LocalizerConfig()
    predicted = truth + np.array([0.03, -0.02, 0.01])
    near = dict(min_inliers=10, max_distance=0.1, max_turn=0.05)
    go = np.random.default_rng(0)
    assert absolute_solution(index, features, no_classes, config, go, predicted, scene,
                             **near) is None                      # 4 matches alone
    wide = absolute_solution(index, features, no_classes, config, go, predicted, scene,
                             **near, measured=(measured_uv, rows))
    tight = absolute_solution(index, features, no_classes, config, go, predicted, scene,
                              **near, measured=(measured_uv, rows),
                              huber_px=config.absolute_huber_px)
    assert wide is not None and tight is not None and tight.inliers >= 20
    off = [np.hypot(*(s.estimate.pose[:2] - truth[:2])) for s in (wide, tight)]
    assert off[1] < 0.002 and off[0] > 3 * off[1]   # (6.3 and 1.3 mm)
    # No SIFT match at all (the ratio test left none): the measurements alone.
    none = (np.full(4, -1), np.full(4, np.inf), np.full(4, np.inf))
    alone = absolute_solution(index, features, no_classes, config, go, predicted, none,
                              **near, measured=(measured_uv, rows),
                              huber_px=config.absolute_huber_px)
    assert alone is not None and np.hypot(*(alone.estimate.pose[:2] - truth[:2])) < 0.002
