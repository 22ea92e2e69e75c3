"""Frames without a pose from the images, bridged by the odometry, by hand."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from landmark_localizer.bridging import INNOVATION_LIMIT, BridgeModel, OdometryBridge

S = 10**8   # 10 Hz
MODEL = BridgeModel(std_per_m=0.05, yaw_deg_per_m=2.0, yaw_std_per_rad=0.05,
                    max_std_m=0.15, max_s=5.0)


def test_the_anchor_moves_by_the_odometry_and_its_covariance_grows_with_the_path() -> None:
    bridge = OdometryBridge()
    anchor_cov = np.diag([1e-6, 1e-6, 1e-6])
    # In map the robot stands at (1, 2) facing +y; its odometry frame is turned by -90 deg.
    bridge.anchor(0, np.array([1.0, 2.0, math.pi / 2]), anchor_cov, np.array([5.0, 0.0, 0.0]))
    # The odometry drives 0.5 m straight ahead (its +x) in five steps.
    for k in range(1, 6):
        out = bridge.bridge(k * S, np.array([5.0 + 0.1 * k, 0.0, 0.0]), MODEL)
    pose, cov = out
    np.testing.assert_allclose(pose, [1.0, 2.5, math.pi / 2], atol=1e-12)
    assert bridge.path_m == pytest.approx(0.5) and bridge.turn_rad == pytest.approx(0.0)
    yaw_std = math.radians(2.0) * 0.5
    xy_var = (0.05 * 0.5) ** 2 + (0.5 * yaw_std) ** 2 / 3.0
    assert cov[2, 2] == pytest.approx(1e-6 + yaw_std ** 2)
    # The anchor's heading error moves the end across the way (along map x) by 0.5 m.
    assert cov[0, 0] == pytest.approx(1e-6 + 0.25 * 1e-6 + xy_var)
    assert cov[1, 1] == pytest.approx(1e-6 + xy_var)


def test_bridging_stops_when_too_wide_too_old_or_without_odometry() -> None:
    bridge = OdometryBridge()
    assert bridge.bridge(S, np.zeros(3), MODEL) is None          # no anchor
    bridge.anchor(0, np.zeros(3), np.eye(3) * 1e-6, np.zeros(3))
    assert bridge.bridge(S, None, MODEL) is None                   # no odometry now
    assert bridge.bridge(6 * 10**9, np.zeros(3), MODEL) is None    # older than 5 s
    # 3 m driven: 5 % is 15 cm along, and the heading's drift adds more: too wide.
    assert bridge.bridge(2 * S, np.array([3.0, 0.0, 0.0]), MODEL) is None
    off = OdometryBridge()
    off.anchor(0, np.zeros(3), np.eye(3) * 1e-6, np.zeros(3))
    assert off.bridge(S, np.array([0.1, 0.0, 0.0]), BridgeModel(max_std_m=0.0)) is None
    # An anchor without odometry cannot be carried.
    lone = OdometryBridge()
    lone.anchor(0, np.zeros(3), np.eye(3) * 1e-6, None)
    assert lone.bridge(S, np.array([0.1, 0.0, 0.0]), MODEL) is None


def _anchored(cov: float = 1e-6) -> OdometryBridge:
    bridge = OdometryBridge()
    bridge.anchor(0, np.zeros(3), np.eye(3) * cov, np.zeros(3))
    return bridge


def test_an_agreeing_pose_is_the_weighted_mean_with_the_images_covariance() -> None:
    odom = np.array([0.1, 0.0, 0.0])
    prediction, predicted_cov = _anchored()._predict(S, odom, MODEL, commit=False)
    image = prediction + np.array([0.002, 0.0, 0.0])
    image_cov = predicted_cov.copy()                  # as certain as the prediction
    pose, published, kept = _anchored().fuse(S, image, image_cov, odom, MODEL)
    np.testing.assert_allclose(pose, prediction + [0.001, 0.0, 0.0], atol=1e-12)
    np.testing.assert_array_equal(published, image_cov)
    # The anchor is not the Kalman update (half of each): the prediction carries the
    # earlier images' errors, so two equal claims stay one claim.
    np.testing.assert_allclose(kept, predicted_cov, atol=1e-15)


def test_the_anchor_never_claims_more_than_either_estimate_nor_shrinks_pose_by_pose() -> None:
    odom = np.array([0.1, 0.0, 0.0])
    rng = np.random.default_rng(3)
    for _ in range(20):
        bridge = _anchored(1e-4)
        prediction, predicted_cov = bridge.predict(S, odom, MODEL)
        root = rng.normal(size=(3, 3)) * 0.01
        image_cov = root @ root.T + np.eye(3) * 1e-6
        _, _, kept = bridge.fuse(S, prediction, image_cov, odom, MODEL)
        kalman = predicted_cov - predicted_cov @ np.linalg.solve(
            predicted_cov + image_cov, predicted_cov)
        assert np.trace(kept[:2, :2]) <= min(np.trace(image_cov[:2, :2]),
                                             np.trace(predicted_cov[:2, :2])) + 1e-15
        assert np.linalg.eigvalsh(kept - kalman).min() >= -1e-12   # never below Kalman's
    # The same image claim fused frame after frame (the same points fix every pose):
    # the anchor stays near what one image claims instead of shrinking towards zero.
    bridge = _anchored(1e-4)
    image_cov = np.diag([1e-4, 1e-4, 1e-4])
    for k in range(1, 31):
        odom_k = np.array([0.001 * k, 0.0, 0.0])
        prediction, _ = bridge.predict(k * S, odom_k, MODEL)
        pose, _, kept = bridge.fuse(k * S, prediction, image_cov, odom_k, MODEL)
        bridge.anchor(k * S, pose, kept, odom_k)
    # (Kalman updates: the thirty-first of it, 0.18 cm claimed for a 1 cm pose.)
    assert 0.9e-4 <= kept[0, 0] <= 1.1e-4


def test_a_vague_pose_that_contradicts_a_sharp_odometry_gives_way_to_it() -> None:
    odom = np.array([0.1, 0.0, 0.0])
    bridge = _anchored()
    prediction, predicted_cov = bridge._predict(S, odom, MODEL, commit=False)
    image = prediction + np.array([0.45, 0.0, 0.0])   # 45 cm off, claiming 10 cm
    image_cov = np.diag([0.01, 0.01, 1e-4])
    nu = image - prediction
    assert nu @ np.linalg.solve(image_cov + predicted_cov, nu) > INNOVATION_LIMIT
    pose, published, kept = bridge.fuse(S, image, image_cov, odom, MODEL)
    assert kept is None
    np.testing.assert_allclose(pose, prediction)
    np.testing.assert_allclose(published, predicted_cov)
    assert bridge.path_m == pytest.approx(0.1)        # the path is counted once
    # A sharp pose that contradicts it is a rival: no pose this frame; the next frame
    # that confirms it (the rival moved by the odometry) wins: the robot was carried.
    sharp = np.eye(3) * 1e-8
    carried = _anchored()
    assert carried.fuse(S, image, sharp, odom, MODEL) == (None, None, None)
    later = np.array([0.2, 0.0, 0.0])
    moved = image + np.array([0.1, 0.0, 0.0])
    pose, published, kept = carried.fuse(2 * S, moved, sharp, later, MODEL)
    np.testing.assert_array_equal(pose, moved)
    np.testing.assert_array_equal(kept, sharp)
    # A weak one (an absolute pose while no region verifies) neither wins nor confirms:
    # two look-alike frames in a row agreeing on the wrong place stay unpublished.
    looked = _anchored()
    assert looked.fuse(S, image, sharp, odom, MODEL, weak=True) == (None, None, None)
    assert looked.fuse(2 * S, moved, sharp, later, MODEL, weak=True) == (None, None, None)
    # A fresh vote wins at once, its covariance grown by the disagreement.
    voted = _anchored()
    pose, published, kept = voted.fuse(S, image, image_cov, odom, MODEL, fresh=True)
    np.testing.assert_array_equal(pose, image)
    np.testing.assert_allclose(published, image_cov + np.outer(nu, nu))
    voted.anchor(S, pose, kept, odom)                  # as the localizer does
    # The doubt stays on what follows (the images agree with the vote whether it found
    # the robot or a look-alike) until the localizer settles it.
    agreeing = image + np.array([0.1, 0.0, 0.0])
    pose, published, kept = voted.fuse(2 * S, agreeing, image_cov, later, MODEL)
    np.testing.assert_allclose(published, image_cov + np.outer(nu, nu))
    voted.anchor(2 * S, pose, kept, later)
    _, bridged = voted.bridge(3 * S, later, MODEL)
    assert bridged[0, 0] >= nu[0] ** 2
    voted.settle()
    pose, published, kept = voted.fuse(4 * S, agreeing, image_cov, later, MODEL)
    np.testing.assert_allclose(published, image_cov)


def test_a_dim_frame_is_brightened_to_the_exposure_target_and_a_bright_one_kept() -> None:
    from landmark_localizer.frames import MAX_EXPOSURE_GAIN, exposed

    ramp = np.tile(np.arange(100, dtype=np.uint8), (10, 1))      # 99th percentile 98
    out = exposed(ramp, 196.0)
    np.testing.assert_array_equal(out[0, :5], [0, 2, 4, 6, 8])   # twice as bright
    assert exposed(ramp, 50.0) is ramp and exposed(ramp, 0.0) is ramp
    dark = np.full((8, 8), 10, np.uint8)
    assert int(exposed(dark, 200.0)[0, 0]) == int(10 * MAX_EXPOSURE_GAIN)


@settings(max_examples=200, derandomize=True, deadline=None)
@given(st.integers(1, 256), st.integers(0, 255), st.floats(0.01, 300.0), st.integers(0, 2**31))
def test_the_bright_frame_shortcut_agrees_with_the_percentile(top, fill, target, seed) -> None:
    """Against the 99th percentile computed from the histogram, at the boundary too: a
    frame with exactly 1 % of its pixels at ceil(target) is dim, one pixel more is not."""
    import math

    from landmark_localizer.frames import MAX_EXPOSURE_GAIN, exposed

    rng = np.random.default_rng(seed)
    image = rng.integers(0, top, (20, 30), dtype=np.uint8)
    image[:, :int(seed % 31)] = fill
    counts = np.cumsum(np.bincount(image.ravel(), minlength=256))
    p99 = int(np.searchsorted(counts, 0.99 * image.size))
    expected = image if p99 >= target else \
        np.clip(np.rint(image * min(MAX_EXPOSURE_GAIN, target / max(p99, 1))), 0, 255)
    np.testing.assert_allclose(exposed(image, target), expected, atol=1)
    assert (exposed(image, target) is image) == (p99 >= target)
    level = min(math.ceil(target), 255)
    edge = np.zeros(1000, np.uint8)
    edge[:10] = level                  # 1 %: the 99th percentile is 0
    assert (exposed(edge, target) is edge) == (level >= target and 0 >= target)
    edge[:11] = level                  # beyond 1 %: the percentile is the level
    assert (exposed(edge, target) is edge) == (level >= target)


def test_the_quality_a_supervisor_acts_on() -> None:
    from landmark_localizer.frames import Estimate, pose_quality

    def estimate(pose, event):
        return Estimate(0, 'LOST', -1, pose, None, None, 0, event, 0.0)

    assert pose_quality(None) == 'lost'
    assert pose_quality(estimate(None, 'withheld')) == 'lost'
    assert pose_quality(estimate(np.zeros(3), 'odometry')) == 'odometry'
    assert pose_quality(estimate(np.zeros(3), 'absolute')) == 'good'


def test_the_absolute_pose_is_searched_near_the_odometrys_prediction() -> None:
    from landmark_localizer.bridging import search_prior
    from landmark_localizer.config import LocalizerConfig

    config = LocalizerConfig()   # bridge: 8 %/m, 2 deg/m, 15 cm, 5 s; 10 and 15 inliers
    assert search_prior(OdometryBridge(), S, np.zeros(3), config) is None   # no anchor
    bridge = _anchored(1e-6)
    pose, radius, turn, need = search_prior(bridge, S, np.array([0.5, 0.0, 0.0]), config)
    np.testing.assert_allclose(pose, [0.5, 0.0, 0.0])
    predicted, cov = bridge.predict(S, np.array([0.5, 0.0, 0.0]), BridgeModel.of(config))
    assert radius == pytest.approx(3 * math.sqrt(max(cov[0, 0], cov[1, 1])))
    assert turn == pytest.approx(3 * math.sqrt(cov[2, 2])) and need == 10
    # Past the bridge's 5 s, the prediction still bounds the search, with more inliers.
    late = search_prior(bridge, 80 * S, np.array([0.5, 0.0, 0.0]), config)
    assert late is not None and late[3] == 15
    assert bridge.predict(80 * S, np.array([0.5, 0.0, 0.0]), BridgeModel.of(config)) is None
    # Until three deviations pass max_jump_m (0.75 m): 5 m driven is too far.
    assert search_prior(bridge, 80 * S, np.array([5.0, 0.0, 0.0]), config) is None
    off = LocalizerConfig(absolute_bridged_min_inliers=0)
    assert search_prior(bridge, S, np.array([0.5, 0.0, 0.0]), off) is None
    # A camera 30 cm ahead of the base: its pose, and the lever arm times the turn more.
    mount = np.array([0.3, 0.0, 0.0])
    camera, wider, same_turn, _ = search_prior(bridge, S, np.array([0.5, 0.0, 0.0]), config,
                                               mount)
    np.testing.assert_allclose(camera, [0.8, 0.0, 0.0])
    assert same_turn == turn and wider == pytest.approx(radius + 0.3 * turn)


def test_the_intersection_tries_the_eleven_weights_at_once_or_one_by_one() -> None:
    """The batched inverses give the weight-by-weight search's result; where one mix is
    singular (an indefinite covariance: the mix at w = 0.5 is) the rest still count."""
    from landmark_localizer.bridging import _intersection

    def by_hand(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        best = a
        for w in np.linspace(0.0, 1.0, 11):
            mix = w * np.linalg.inv(a) + (1 - w) * np.linalg.inv(b)
            if abs(np.linalg.det(mix)) < 1e-12:
                continue
            joined = np.linalg.inv(mix)
            if np.trace(joined[:2, :2]) < np.trace(best[:2, :2]):
                best = joined
        return 0.5 * (best + best.T)

    rng = np.random.default_rng(5)
    for _ in range(20):
        m, n = rng.normal(size=(2, 3, 3))
        a, b = m @ m.T + 0.01 * np.eye(3), n @ n.T + 0.01 * np.eye(3)
        np.testing.assert_allclose(_intersection(a, b), by_hand(a, b), rtol=1e-9, atol=1e-15)
    a, b = np.eye(3), np.diag([1.0, 1.0, -1.0])
    np.testing.assert_allclose(_intersection(a, b), by_hand(a, b))
