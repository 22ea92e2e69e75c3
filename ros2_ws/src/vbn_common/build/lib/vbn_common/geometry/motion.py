"""The result and settings of the two-view solvers (thesis Sections 7.3 to 7.5).

Conventions in :mod:`vbn_common.geometry.two_view`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import numpy as np

from vbn_common.errors import VbnCommonError

__all__ = ['RelativeMotion', 'TwoViewConfig']


@dataclass(frozen=True)
class RelativeMotion:
    """The motion from a model view to the current view (module conventions).

    Attributes:
        theta: the current camera's yaw relative to the model camera's, radians in
            ``[-pi, pi)``, counter-clockwise seen from above.
        direction: unit vector from the model camera to the current camera in the
            model camera's planar frame (``x`` forward, ``y`` left): ``(2,)`` for the
            planar methods, ``(3,)`` (``z`` up) for :func:`general_essential`.
        inliers: ``(n,)`` bool, the correspondences the estimate kept.
        residual: RMS Sampson angular error of the inliers, radians.
        method: the method's name.
        covariance: ``(2, 2)`` covariance of ``(theta, phi)``, radians squared, where
            ``phi = atan2(direction[1], direction[0])`` is the planar bearing of the
            translation; from the inliers' residuals and the Jacobian of the planar
            epipolar errors.
        rotation: ``(3, 3)`` rotation of the model camera's planar (REP 103) frame
            into the current one's, ``x_current = rotation @ x_model`` for
            directions; a rotation about ``z`` by ``-theta`` except for
            :func:`general_essential`.
    """

    theta: float
    direction: np.ndarray
    inliers: np.ndarray
    residual: float
    method: str
    covariance: np.ndarray = field(default_factory=lambda: np.full((2, 2), np.nan))
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    @property
    def phi(self) -> float:
        """Return the planar bearing of the translation, ``atan2(d_y, d_x)``, radians."""
        return float(math.atan2(self.direction[1], self.direction[0]))

    @property
    def planar_direction(self) -> np.ndarray:
        """Return the translation's unit ``(2,)`` direction in the plane."""
        d = np.asarray(self.direction[:2], dtype=float)
        return d / np.linalg.norm(d)


@dataclass(frozen=True)
class TwoViewConfig:
    """Parameters of the two-view solvers (pixels are converted with the camera).

    Attributes:
        threshold_px: inlier threshold on the Sampson error, pixels.
        min_elevation_deg: panoramic method: correspondences with an elevation below
            this in either view are not used (``cot`` of the elevation explodes near
            the horizon, eq. 7.20).
        max_pairs: panoramic method: at most this many correspondence pairs
            (random, with ``rng``) propose rotations; all pairs when there are fewer.
        max_iterations: RANSAC hypotheses at most.
        confidence: RANSAC stops when an all-inlier sample was drawn with this
            probability.
        refine: polish ``(theta, phi)`` of the planar methods by Gauss-Newton on the
            inliers' Sampson errors.
        noise_floor_px: smallest noise assumed for the covariance, pixels (exact
            data would otherwise give a zero covariance).
        min_parallax_px: the median parallax after undoing the rotation must exceed
            this, pixels, and 2.5 times the inliers' RMS epipolar error (the ratio
            measured 1.3 to 2.3 for identical poses with 0.5 px of noise, 1.8 to 3.8
            for 2 cm apart, 2.3 to 8 for 5 cm); otherwise the views are (nearly) at
            the same place and the direction of translation is undetermined.
        min_parallax_ratio: the factor 2.5 above (0 disables this test).
    """

    threshold_px: float = 1.5
    min_elevation_deg: float = 2.0
    max_pairs: int = 1500
    max_iterations: int = 1000
    confidence: float = 0.999
    refine: bool = True
    noise_floor_px: float = 0.1
    min_parallax_px: float = 0.25
    min_parallax_ratio: float = 2.5

    def __post_init__(self) -> None:
        """Reject invalid values with a :class:`VbnCommonError`."""
        for name in ('threshold_px', 'min_parallax_px', 'noise_floor_px'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise VbnCommonError(f'{name} must be a positive number, got {value}')
        if not (math.isfinite(self.min_parallax_ratio) and self.min_parallax_ratio >= 0):
            raise VbnCommonError(f'min_parallax_ratio must be >= 0, got '
                                 f'{self.min_parallax_ratio}')
        if not 0.0 <= self.min_elevation_deg < 90.0:
            raise VbnCommonError(
                f'min_elevation_deg must be in [0, 90), got {self.min_elevation_deg}')
        if self.max_pairs < 1 or self.max_iterations < 1:
            raise VbnCommonError(f'max_pairs and max_iterations must be >= 1, got '
                                 f'{self.max_pairs} and {self.max_iterations}')
        if not 0.0 < self.confidence < 1.0:
            raise VbnCommonError(f'confidence must be in (0, 1), got {self.confidence}')


