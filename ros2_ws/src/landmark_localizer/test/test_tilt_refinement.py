"""The pose refinement with the frame's own pitch, roll and height (tilt_refinement.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landmark_localizer.tilt_refinement import (
    marginal_covariance,
    refine_tilted,
    tilted_residuals,
)
from vbn_common.geometry.epipolar import pointwise_planar_residuals
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION, wrap_angle
from vbn_common.geometry.mount import tilt_matrix

VIEWS = np.array([[0.5, 0.2, 0.3], [-0.4, 0.6, -0.5]])


def _scene(rng: np.random.Generator) -> np.ndarray:
    points = np.column_stack([rng.uniform(-3, 3, 200), rng.uniform(-3, 3, 200),
                              rng.uniform(-1, 1, 200)])
    points[:, 0] += np.sign(points[:, 0]) * 2.0
    return points


def _rays(points: np.ndarray, pose: np.ndarray, z: float = 0.0,
          tilt: np.ndarray | None = None) -> np.ndarray:
    """Optical rays of a camera at ``pose`` and height ``z`` with its own tilt."""
    d = points - np.r_[pose[:2], z]
    c, s = math.cos(pose[2]), math.sin(pose[2])
    planar = np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])
    optical = planar @ BASE_TO_CAMERA_ROTATION           # level optical frame
    if tilt is not None:
        optical = optical @ tilt                         # ray = tilt^T ray_level
    return optical / np.linalg.norm(optical, axis=1, keepdims=True)


def _data(points: np.ndarray, current: np.ndarray, z: float = 0.0,
          tilt: np.ndarray | None = None):
    view = np.repeat([0, 1], len(points))
    model = np.vstack([_rays(points, VIEWS[0]), _rays(points, VIEWS[1])])
    now = np.vstack([_rays(points, current, z, tilt)] * 2)
    return view, model, now


def test_level_states_give_the_planar_sampson_errors() -> None:
    points = _scene(np.random.default_rng(0))
    truth = np.array([0.1, -0.2, 0.2])
    view, model, now = _data(points, truth)
    state = np.r_[truth + [0.01, 0.0, 0.002], 0.0, 0.0, 0.0]
    ours = tilted_residuals(state[None], VIEWS, view, model, now)[0]
    vp = VIEWS[view]
    dx, dy = state[0] - vp[:, 0], state[1] - vp[:, 1]
    c, s = np.cos(vp[:, 2]), np.sin(vp[:, 2])
    planar = pointwise_planar_residuals(model, now, wrap_angle(state[2] - vp[:, 2]),
                                        np.arctan2(-s * dx + c * dy, c * dx + s * dy))
    np.testing.assert_allclose(np.abs(ours), np.abs(planar), atol=1e-7)
    assert np.abs(ours).max() > 1e-4


def test_the_frames_tilt_and_height_are_recovered() -> None:
    points = _scene(np.random.default_rng(1))
    truth = np.array([0.1, -0.2, 0.2, math.radians(0.7), math.radians(-0.4), 0.05])
    view, model, now = _data(points, truth[:3], truth[5],
                             tilt_matrix(math.degrees(truth[3]), math.degrees(truth[4])))
    assert np.abs(tilted_residuals(truth[None], VIEWS, view, model, now)).max() < 1e-12
    state, r, jac = refine_tilted(truth[:3] + [0.02, -0.01, 0.003], VIEWS, view, model, now,
                                  threshold=1e-3, noise=1e-3, tilt_prior_deg=1.0,
                                  height_prior_m=0.1)
    assert state == pytest.approx(truth, abs=1e-5)
    assert np.abs(r).max() < 1e-6 and jac.shape == (len(r), 6)   # the priors pull a little
    cov = marginal_covariance(jac, 1e-8, 1e-3, 1.0, 0.1)
    assert cov.shape == (3, 3) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_the_priors_hold_what_the_points_cannot_tell() -> None:
    # A level camera with noisy rays: pitch, roll and height stay near zero.
    rng = np.random.default_rng(2)
    points = _scene(rng)
    truth = np.array([0.1, -0.2, 0.2])
    view, model, now = _data(points, truth)
    now = now + rng.normal(0.0, 1e-3, now.shape)
    now /= np.linalg.norm(now, axis=1, keepdims=True)
    state, _, _ = refine_tilted(truth, VIEWS, view, model, now, threshold=3e-3, noise=1e-3,
                                tilt_prior_deg=1.0, height_prior_m=0.1)
    assert abs(math.degrees(state[3])) < 0.2 and abs(math.degrees(state[4])) < 0.2
    assert abs(state[5]) < 0.02 and np.linalg.norm(state[:2] - truth[:2]) < 0.02
