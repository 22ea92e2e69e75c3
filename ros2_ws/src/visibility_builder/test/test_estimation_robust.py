"""The robust steps of the pose estimation: L1 angles, bearings under fitted turns,
positions without the linear fit's shrinkage, no rotation alone between places."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from vbn_common.features import ImageFeatures
from vbn_common.geometry.camera import PanoramicCamera
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.pipeline import matrix_to_quat
from visibility_builder.estimation.positions import fit_positions, refine_planar_positions
from visibility_builder.estimation.rotations import (
    fit_rotations,
    planar_l1_angles,
    quat_conj,
    quat_from_yaw,
    quat_mul,
    quat_yaw,
)
from visibility_builder.estimation.view_pairs import (
    PairMotion,
    PairSettings,
    bearings_given_turns,
    measure_pair,
)

RING = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 5], [5, 0], [0, 2], [1, 3], [2, 4],
                 [3, 5], [4, 0], [5, 1]])


def _wrap(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(a, float)))


def test_l1_angles_let_the_majority_outvote_a_confident_wrong_pair() -> None:
    """Six views, twelve pairs; one pair 10 degrees off claims 2.5 times the weight of
    the others: the L1 angles are exact, the least squares are pulled off."""
    yaw = np.radians([0.0, 50.0, 100.0, 170.0, -120.0, -60.0])
    measured = yaw[RING[:, 1]] - yaw[RING[:, 0]]
    measured[3] += math.radians(10.0)
    weights = np.ones(len(RING))
    weights[3] = 2.5
    start = yaw + np.radians([0.0, 3.0, -4.0, 5.0, 2.0, -3.0])
    angles = planar_l1_angles(6, RING, measured, weights, start)
    assert _wrap(angles - yaw) == pytest.approx(np.zeros(6), abs=1e-9)
    # The least squares over quaternions (weights squared) share the error out.
    rel = quat_from_yaw(measured)
    fit = fit_rotations(6, RING, rel, weights ** 2)
    ls = quat_yaw(quat_mul(fit.quaternions, quat_conj(fit.quaternions[0])))
    assert np.degrees(np.abs(_wrap(ls - yaw))).max() > 1.0


def test_l1_angles_unwrap_across_half_a_turn_and_keep_the_anchor() -> None:
    yaw = np.radians([10.0, 178.0, -176.0, 90.0])
    pairs = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]])
    measured = _wrap(yaw[pairs[:, 1]] - yaw[pairs[:, 0]]) + 2 * math.pi * np.array(
        [1, -1, 0, 2, -1])                  # any branch
    angles = planar_l1_angles(4, pairs, measured, np.ones(5), yaw + 0.05, anchor=0)
    assert angles[0] == pytest.approx(yaw[0] + 0.05)
    assert _wrap(angles - angles[0] - (yaw - yaw[0])) == pytest.approx(np.zeros(4), abs=1e-9)


@settings(max_examples=15, deadline=None, derandomize=True)
@given(st.integers(0, 10_000))
def test_l1_angles_with_noise_stay_within_it(seed: int) -> None:
    rng = np.random.default_rng(seed)
    yaw = rng.uniform(-math.pi, math.pi, 6)
    yaw[0] = 0.0
    noise = math.radians(0.1)
    measured = yaw[RING[:, 1]] - yaw[RING[:, 0]] + rng.normal(0, noise, len(RING))
    angles = planar_l1_angles(6, RING, measured, np.ones(len(RING)),
                              yaw + rng.normal(0, 0.1, 6))
    assert np.abs(_wrap(angles - angles[0] - yaw)).max() < 6 * noise


def test_l1_angles_refuse_bad_input() -> None:
    with pytest.raises(VisibilityBuilderError, match='differ in length'):
        planar_l1_angles(3, RING[:2], np.zeros(3), np.ones(2), np.zeros(3))
    with pytest.raises(VisibilityBuilderError, match='positive'):
        planar_l1_angles(3, RING[:2], np.zeros(2), np.array([1.0, 0.0]), np.zeros(3))


def _panoramic_pair(theta: float, phi: float, rng: np.random.Generator
                    ) -> tuple[PanoramicCamera, list[ImageFeatures], np.ndarray]:
    """Features of two panoramas: view 1 at ``(cos phi, sin phi) * 0.5`` turned by theta."""
    camera = PanoramicCamera(width=1024, height=256)
    points = np.c_[rng.uniform(-4, 4, 400), rng.uniform(-4, 4, 400), rng.uniform(-0.6, 0.6, 400)]
    points = points[np.abs(points[:, :2]).max(axis=1) > 2.0]
    poses = [(0.0, 0.0, 0.0), (0.5 * math.cos(phi), 0.5 * math.sin(phi), theta)]
    features, visible = [], np.ones(len(points), bool)
    uvs = []
    for x, y, yaw in poses:
        d = points - [x, y, 0.0]
        c, s = math.cos(yaw), math.sin(yaw)
        planar = np.c_[c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]]
        uv, ok = camera.project(planar @ BASE_TO_CAMERA_ROTATION)
        visible &= ok
        uvs.append(uv)
    for uv in uvs:
        k = int(visible.sum())
        features.append(ImageFeatures(uv[visible].astype(np.float32), np.ones(k, np.float32),
                                      np.zeros(k, np.float32), np.ones(k, np.float32),
                                      np.zeros((k, 128), np.uint8)))
    index = np.arange(int(visible.sum()))
    return camera, features, np.c_[index, index]


def test_a_bearing_under_the_true_turn_is_pulled_back_exactly() -> None:
    """The pair claims a bearing 5 degrees off; held at the true turn it comes back."""
    theta, phi = math.radians(30.0), math.radians(-70.0)
    camera, features, matches = _panoramic_pair(theta, phi, np.random.default_rng(3))
    wrong = phi + math.radians(5.0)
    pair = PairMotion(0, 1, np.eye(3), np.array([math.cos(wrong), math.sin(wrong), 0.0]),
                      1e-3, 1e-3, len(matches), len(matches), 0.0, 'panoramic_planar',
                      matches)
    bearing, std = bearings_given_turns([pair], np.array([theta]), features, camera,
                                        PairSettings())
    assert bearing[0] == pytest.approx(phi, abs=1e-7)
    assert 0 < std[0] < math.radians(0.1)


def test_positions_keep_the_odometry_scale_where_the_linear_fit_shrinks() -> None:
    """A 3 x 3 grid, every pair, exact bearings claiming 1 mrad, odometry with 2 cm: the linear fit
    with the odometry comes out small when two confident bearings are 3 degrees off;
    the robust non-linear fit keeps the scale and the shape within half a centimetre
    (the wrong bearings alone would move a view by 2.6 cm)."""
    xy = np.array([[x, y] for y in (0.0, 0.5, 1.0) for x in (0.0, 0.5, 1.0)])
    pairs = np.array([(a, b) for a in range(9) for b in range(a + 1, 9)])
    d = xy[pairs[:, 1]] - xy[pairs[:, 0]]
    bearings = np.arctan2(d[:, 1], d[:, 0])
    bearings[[0, -1]] += math.radians(3.0)       # views 0-1 and 7-8
    std = np.full(len(pairs), 1e-3)
    odo_pairs = np.c_[np.arange(8), np.arange(1, 9)]
    odometry = (odo_pairs, np.diff(xy, axis=0), np.full(8, 1.0 / 0.02 ** 2))
    lengths = np.linalg.norm(d, axis=1)
    dirs = np.c_[np.cos(bearings), np.sin(bearings)]
    linear = fit_positions(9, pairs, dirs, 1.0 / (std * lengths) ** 2, odometry=odometry,
                           max_angle=math.radians(20))
    linear_size = np.linalg.norm(linear.positions - linear.positions.mean(0), axis=1).sum()
    true_size = np.linalg.norm(xy - xy.mean(0), axis=1).sum()
    assert linear_size < 0.98 * true_size
    refined, miss = refine_planar_positions(linear.positions, pairs, bearings, std, odometry)
    assert refined == pytest.approx(xy, abs=5e-3)
    size = np.linalg.norm(refined - refined.mean(0), axis=1).sum()
    assert size == pytest.approx(true_size, rel=2e-3)
    assert np.degrees(miss[[0, -1]]).min() > 2.5          # the wrong bearings stand out
    assert np.degrees(np.delete(miss, [0, len(miss) - 1])).max() < 1.0
    # Exact bearings from a shrunk start: exact.
    refined, miss = refine_planar_positions(0.7 * xy, pairs, np.arctan2(d[:, 1], d[:, 0]),
                                            std, odometry)
    assert refined == pytest.approx(xy, abs=1e-7)
    assert miss.max() < 1e-7


def test_positions_refuse_bad_input() -> None:
    odometry = (np.array([[0, 1]]), np.array([[1.0, 0.0]]), np.ones(1))
    with pytest.raises(VisibilityBuilderError, match='finite'):
        refine_planar_positions(np.array([[0.0, 0.0], [np.nan, 0.0]]), np.array([[0, 1]]),
                                np.zeros(1), np.ones(1), odometry)
    with pytest.raises(VisibilityBuilderError, match='positive'):
        refine_planar_positions(np.zeros((2, 2)), np.array([[0, 1]]), np.zeros(1),
                                np.zeros(1), odometry)


def test_views_without_parallax_are_a_rotation_only_where_the_robot_stood_still() -> None:
    """Two panoramas from one place: a rotation alone, unless the odometry moved."""
    camera, features, _ = _panoramic_pair(math.radians(20.0), 0.0, np.random.default_rng(5))
    rng = np.random.default_rng(6)
    descriptors = rng.integers(0, 255, (len(features[0]), 128)).astype(np.uint8)
    # The second view at the first one's place: the first view's rays turned by 20 deg.
    rays = camera.unproject(features[0].keypoints.astype(float)) @ BASE_TO_CAMERA_ROTATION.T
    c, s = math.cos(math.radians(20.0)), math.sin(math.radians(20.0))
    turned = np.c_[c * rays[:, 0] + s * rays[:, 1], -s * rays[:, 0] + c * rays[:, 1], rays[:, 2]]
    uv, ok = camera.project(turned @ BASE_TO_CAMERA_ROTATION)
    assert ok.all()
    a = ImageFeatures(features[0].keypoints, features[0].sizes, features[0].angles,
                      features[0].responses, descriptors)
    b = ImageFeatures(uv.astype(np.float32), features[0].sizes, features[0].angles,
                      features[0].responses, descriptors)
    still, why = measure_pair(0, 1, a, b, camera, PairSettings(), moved=False)
    assert why == '' and still is not None and still.method == 'rotation_only'
    turn = -quat_yaw(matrix_to_quat(still.rotation))
    assert math.degrees(turn) == pytest.approx(20.0, abs=0.05)
    moved, why = measure_pair(0, 1, a, b, camera, PairSettings(), moved=True)
    assert moved is None and why.startswith('no parallax')


def test_similarity_figures_by_hand() -> None:
    """An estimate 0.2 % small and turned: scale 1.002 back, zero error after a similarity."""
    from visibility_builder.estimation.accuracy import centre_errors_sim3, similarity_scale

    truth = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.1], [4.0, 3.0, 0.0], [0.0, 3.0, -0.2]])
    c, s = math.cos(0.7), math.sin(0.7)
    turned = truth @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    estimate = turned / 1.002 + [5.0, -2.0, 1.0]
    assert similarity_scale(estimate, truth) == pytest.approx(1.002, abs=1e-9)
    assert centre_errors_sim3(estimate, truth) == pytest.approx(np.zeros(4), abs=1e-9)
    shifted = estimate.copy()
    shifted[0, 0] += 0.01
    assert np.nanmax(centre_errors_sim3(shifted, truth)) > 0.003
    assert np.isnan(centre_errors_sim3(estimate[:2], truth[:2])).all()   # too few points
