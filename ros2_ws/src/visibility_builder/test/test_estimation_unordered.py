"""Unordered photographs of a hand-held camera: the general path of thesis 6.1."""
from __future__ import annotations

import math

import numpy as np
import pytest

from vbn_common.features import ImageFeatures
from vbn_common.geometry.camera import PinholeCamera
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.estimation.accuracy import centre_errors_sim3
from visibility_builder.estimation.unordered import estimate_unordered

CAMERA = PinholeCamera(width=640, height=480, fx=500.0, fy=500.0, cx=319.5, cy=239.5)


def _look_at(centre: np.ndarray, target: np.ndarray, roll: float) -> np.ndarray:
    """Rows: the optical frame's axes in the world (world into optical)."""
    z = target - centre
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    return np.array([c * x + s * y, -s * x + c * y, z])


def _photographs(noise_px: float, rng: np.random.Generator
                 ) -> tuple[list[ImageFeatures], np.ndarray]:
    """Six photographs on an arc round a cloud of points, at several heights and rolls."""
    points = rng.uniform(-1.5, 1.5, (600, 3))
    descriptors = rng.integers(0, 256, (len(points), 128)).astype(np.uint8)
    centres, features = [], []
    for k in range(6):
        angle = math.radians(-50 + 20 * k)
        centre = np.array([6 * math.cos(angle), 6 * math.sin(angle), 0.4 * (k % 3) - 0.4])
        rotation = _look_at(centre, rng.normal(0, 0.2, 3), math.radians(5 * (k - 2)))
        optical = (points - centre) @ rotation.T
        uv, ok = CAMERA.project(optical)
        uv = uv + rng.normal(0, noise_px, uv.shape)
        keep = np.flatnonzero(ok)
        features.append(ImageFeatures(uv[keep].astype(np.float32),
                                      np.ones(len(keep), np.float32),
                                      np.zeros(len(keep), np.float32),
                                      np.ones(len(keep), np.float32), descriptors[keep]))
        centres.append(centre)
    return features, np.array(centres)


def test_exact_photographs_give_the_cameras_up_to_a_similarity() -> None:
    features, centres = _photographs(0.0, np.random.default_rng(1))
    estimate = estimate_unordered(features, CAMERA)
    assert len(estimate.pairs) == 15 and estimate.kept_direction.all()
    for found in (estimate.thesis_centres, estimate.centres):
        errors = centre_errors_sim3(found, centres)
        assert np.isfinite(errors).all()
        assert errors.max() < 1e-3 * 12                  # a thousandth of the arc's span
    assert centre_errors_sim3(estimate.centres, centres).max() < 1e-4
    assert estimate.rms_px < 0.05


def test_noisy_photographs_stay_within_the_noise_and_refinement_helps() -> None:
    features, centres = _photographs(0.5, np.random.default_rng(2))
    estimate = estimate_unordered(features, CAMERA)
    thesis = centre_errors_sim3(estimate.thesis_centres, centres)
    refined = centre_errors_sim3(estimate.centres, centres)
    assert np.median(refined) < 0.01                     # 1 cm on a 6 m arc, 0.5 px noise
    assert np.median(refined) <= np.median(thesis)
    assert 0.3 < estimate.rms_px < 0.8


def test_no_overlap_is_one_clear_error() -> None:
    features, _ = _photographs(0.0, np.random.default_rng(3))
    rng = np.random.default_rng(4)
    strangers = [ImageFeatures(f.keypoints, f.sizes, f.angles, f.responses,
                               rng.integers(0, 256, f.descriptors.shape).astype(np.uint8))
                 for f in features[:2]]
    with pytest.raises(VisibilityBuilderError, match='no two images overlap'):
        estimate_unordered(strangers, CAMERA)
    with pytest.raises(VisibilityBuilderError, match='at least two'):
        estimate_unordered(features[:1], CAMERA)


def test_a_stray_first_photograph_leaves_the_others_posed() -> None:
    """Image 0 shares nothing with the rest: the largest group is estimated without it."""
    features, centres = _photographs(0.0, np.random.default_rng(5))
    rng = np.random.default_rng(6)
    stray = features[0]
    features[0] = ImageFeatures(stray.keypoints, stray.sizes, stray.angles, stray.responses,
                                rng.integers(0, 256, stray.descriptors.shape).astype(np.uint8))
    estimate = estimate_unordered(features, CAMERA)
    assert np.isnan(estimate.centres[0]).all()
    errors = centre_errors_sim3(estimate.centres, centres)
    assert np.isfinite(errors[1:]).all() and errors[1:].max() < 1e-4
