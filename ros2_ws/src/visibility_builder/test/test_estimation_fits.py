"""Rotations (thesis 6.1.3) and positions (6.1.4) of views from pairwise motions."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.pipeline import matrix_to_quat
from visibility_builder.estimation.positions import fit_positions
from visibility_builder.estimation.rotations import (
    fit_rotations,
    quat_angle,
    quat_conj,
    quat_from_yaw,
    quat_mul,
    quat_to_matrix,
)

SQUARE = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
SQUARE_PAIRS = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]])


def _relative(q: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    return quat_mul(q[pairs[:, 1]], quat_conj(q[pairs[:, 0]]))


def _directions(xy: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    d = xy[pairs[:, 1]] - xy[pairs[:, 0]]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_quaternion_helpers_by_hand() -> None:
    q = quat_from_yaw(np.array([math.pi / 2]))[0]
    assert quat_to_matrix(q) @ np.array([1.0, 0, 0]) == pytest.approx([0, 1, 0])
    assert quat_angle(quat_mul(q, q)) == pytest.approx(math.pi)
    r = quat_to_matrix(np.array([0.3, -0.2, 0.5, 0.7]))
    back = matrix_to_quat(r)
    assert abs(abs(back @ (np.array([0.3, -0.2, 0.5, 0.7]) / np.linalg.norm(
        [0.3, -0.2, 0.5, 0.7]))) - 1.0) < 1e-12


def test_square_of_four_views_exact() -> None:
    """Yaws 0, 90, 180, 270 degrees: the fit returns them, whatever sign each q_ij has."""
    yaw = np.radians([0.0, 90.0, 180.0, 270.0])
    q = quat_from_yaw(-yaw)                       # world into camera
    rel = _relative(q, SQUARE_PAIRS) * np.array([1, -1, 1, -1, -1])[:, None]
    fit = fit_rotations(4, SQUARE_PAIRS, rel, np.ones(5))
    assert quat_angle(quat_mul(fit.quaternions, quat_conj(q))).max() < 1e-9
    assert fit.residual.max() < 1e-9
    positions = fit_positions(4, SQUARE_PAIRS, _directions(SQUARE, SQUARE_PAIRS), np.ones(5))
    scale = 1.0 / positions.positions[1, 0]
    assert positions.positions * scale == pytest.approx(SQUARE, abs=1e-6)
    assert positions.lengths * scale == pytest.approx([1, 1, 1, 1, math.sqrt(2)], abs=1e-6)
    assert positions.scale_from == 'unit'


def test_a_chain_of_collinear_views_needs_the_odometry() -> None:
    """Directions along a line fix no lengths: the odometry's displacements do."""
    xy = np.array([[0.0, 0.0], [0.3, 0.0], [0.5, 0.0], [0.9, 0.0]])
    pairs = np.array([[0, 1], [1, 2], [2, 3], [0, 2]])
    odometry = (np.array([[0, 1], [1, 2], [2, 3]]), np.diff(xy, axis=0), np.full(3, 1e4))
    fit = fit_positions(4, pairs, _directions(xy, pairs), np.ones(4), odometry=odometry)
    assert fit.positions == pytest.approx(xy, abs=1e-6)
    assert fit.scale_from == 'odometry'


def test_a_disconnected_view_stays_unknown() -> None:
    pairs = np.array([[0, 1], [1, 2], [0, 2]])
    xy = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [5.0, 5.0]])
    fit = fit_positions(4, pairs, _directions(xy, pairs), np.ones(3))
    assert np.isnan(fit.positions[3]).all()
    assert np.isfinite(fit.positions[:3]).all()
    rot = fit_rotations(4, pairs, quat_from_yaw(np.zeros(3)), np.ones(3))
    assert rot.connected.tolist() == [True, True, True, False]
    assert np.isnan(rot.quaternions[3]).all()


def test_an_outlier_direction_is_dropped() -> None:
    xy = np.array([[x, y] for y in range(3) for x in range(4)], float)
    pairs = np.array([(i, j) for i in range(12) for j in range(i + 1, 12)
                      if np.linalg.norm(xy[i] - xy[j]) < 1.5])
    directions = _directions(xy, pairs)
    directions[4] = -directions[4]
    fit = fit_positions(12, pairs, directions, np.ones(len(pairs)))
    assert not fit.kept[4] and fit.kept.sum() == len(pairs) - 1
    scale = 1.0 / np.linalg.norm(fit.positions[1])
    assert fit.positions * scale == pytest.approx(xy - xy[0], abs=1e-6)


def test_bad_input_is_refused() -> None:
    with pytest.raises(VisibilityBuilderError, match='differ in length'):
        fit_rotations(3, np.array([[0, 1]]), np.zeros((2, 4)), np.ones(1))
    with pytest.raises(VisibilityBuilderError, match='outside'):
        fit_rotations(2, np.array([[0, 2]]), quat_from_yaw(np.zeros(1)), np.ones(1))
    with pytest.raises(VisibilityBuilderError, match='positive'):
        fit_rotations(2, np.array([[0, 1]]), quat_from_yaw(np.zeros(1)), np.zeros(1))
    with pytest.raises(VisibilityBuilderError, match='non-zero'):
        fit_positions(2, np.array([[0, 1]]), np.zeros((1, 2)), np.ones(1))


@settings(max_examples=25, deadline=None, derandomize=True)
@given(seed=st.integers(0, 10_000), noise=st.sampled_from([0.0, 0.002]))
def test_random_grids_recover_poses_within_the_noise(seed: int, noise: float) -> None:
    """A 6 x 4 grid of views at random headings: errors of the order of the noise."""
    rng = np.random.default_rng(seed)
    xy = np.array([[x, y] for y in range(4) for x in range(6)], float) * 0.25
    n = len(xy)
    pairs = np.array([(i, j) for i in range(n) for j in range(i + 1, n)
                      if np.linalg.norm(xy[i] - xy[j]) < 0.6])
    yaw = rng.uniform(-math.pi, math.pi, n)
    q = quat_from_yaw(-yaw)
    rel = quat_mul(quat_from_yaw(rng.normal(0, noise, len(pairs))), _relative(q, pairs))
    rot = fit_rotations(n, pairs, rel, np.ones(len(pairs)))
    anchor = quat_mul(quat_conj(q[0]), rot.quaternions[0])   # the fit's world is view 0's
    error = quat_angle(quat_mul(rot.quaternions, quat_conj(quat_mul(q, anchor))))
    assert error.max() <= 10 * noise + 1e-9
    turn = rng.normal(0, noise, len(pairs))
    d = _directions(xy, pairs)
    c, s = np.cos(turn), np.sin(turn)
    noisy = np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1)
    fit = fit_positions(n, pairs, noisy, np.ones(len(pairs)))
    est = fit.positions * (0.25 / np.linalg.norm(fit.positions[1]))
    assert np.abs(est - (xy - xy[0])).max() <= 40 * noise * 0.25 * n ** 0.5 + 1e-6
