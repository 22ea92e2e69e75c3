"""The current camera's pose from its motion relative to model views of known pose (7.4).

Each model view ``k`` has a known pose in ``map`` and a
:class:`~vbn_common.geometry.motion.RelativeMotion` to the current view; the current
camera lies on the ray from the model camera along the motion's direction, which two
views fix only up to its length. Two rays (the thesis's two model views of a region) meet at the
current position: ``u = v + lambda T_vu = w + mu T_wu`` (Section 7.4, solved here as
least squares in ``map``). :func:`position_from_views` takes any number of views:
where the robot stands near the line through two model views their rays are nearly
parallel and a further model view, off that line, fixes the position.

Conventions:

- A model view's pose is the *camera's* planar pose in ``map``: ``(x, y, yaw)``, the
  camera's centre on the floor and the yaw of its forward axis (optical ``z``; the
  panorama's azimuth zero), as :attr:`vbn_common.exploration.Frame.camera_pose`
  gives it. The result is the current *camera's* pose in ``map`` in the same
  convention (the samples' camera sits above ``base_link`` looking along its ``x``
  axis, so it is the base pose too).
- The ray of view ``k`` is ``p_k + lambda d_k`` with ``d_k = R(yaw_k) direction_k``.
- Uncertainty: a ray's angle ``phi_k`` has the variance the motion reports
  (``motion.covariance[1, 1]``), so the position's distance from the ray has the
  standard deviation ``|u - p_k| sigma_phi_k``; the position's covariance is the
  inverse of the weighted normal matrix ``sum_k n_k n_k^T / sigma_k^2`` (``n_k`` the
  ray's normal), inflated by the reduced chi-square when more than two rays disagree.
  Two rays at an angle ``a`` give a covariance that grows as ``1 / sin(a)^2`` along
  their bisector. The heading is the weighted circular mean of ``yaw_k + theta_k``
  with weights ``1 / var(theta_k)``; the covariance between heading and position is
  left zero.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import logging
import math

import numpy as np

from vbn_common.errors import VbnCommonError
from vbn_common.geometry.frames import wrap_angle
from vbn_common.geometry.motion import RelativeMotion

__all__ = ['PoseEstimate', 'position_from_two_views', 'position_from_views']

_LOG = logging.getLogger(__name__)

#: Variance used for a motion without a finite one, rad^2 (a 0.1 rad ray).
_DEFAULT_VARIANCE = 1e-2


@dataclass(frozen=True)
class PoseEstimate:
    """The current camera's planar pose in ``map`` with its uncertainty.

    Attributes:
        x: metres in ``map``.
        y: metres in ``map``.
        yaw: heading of the camera's forward axis, radians in ``[-pi, pi)``.
        covariance: ``(3, 3)`` covariance of ``(x, y, yaw)`` (m^2, rad^2).
        ray_angle: the largest angle between two of the rays, radians in
            ``[0, pi / 2]`` (0: parallel rays, position undetermined along them).
        residual: RMS distance of the position from the rays, metres (0 for two rays).
        n_views: the number of model views used.
        in_front: every ray points towards the position (``(u - p_k) . d_k > 0``);
            ``False`` means the directions disagree with the geometry.
    """

    x: float
    y: float
    yaw: float
    covariance: np.ndarray
    ray_angle: float
    residual: float
    n_views: int
    in_front: bool

    @property
    def pose(self) -> np.ndarray:
        """Return ``(3,)`` ``(x, y, yaw)``."""
        return np.array([self.x, self.y, self.yaw])


def _variance(value: float) -> float:
    return float(value) if math.isfinite(value) and value > 0 else _DEFAULT_VARIANCE


def position_from_views(view_poses: np.ndarray, motions: Sequence[RelativeMotion], *,
                        min_ray_angle: float = 1e-6) -> PoseEstimate:
    """Intersect the rays from two or more model views to the current camera (7.4).

    Weighted least squares in ``map``: the position minimises the sum over views of
    the squared distances from the rays, each divided by its variance
    ``(|u - p_k| sigma_phi_k)^2`` (two passes: unweighted, then weighted at the first
    solution), so a far or uncertain view counts less. See the module docstring for
    the conventions and the covariance.

    Args:
        view_poses: ``(k, 3)`` camera poses ``(x, y, yaw)`` of the model
            views in ``map``.
        motions: the ``k`` motions from each model view to the current view.
        min_ray_angle: rays closer to parallel than this (radians) are refused.

    Returns:
        The current camera's pose and its covariance.

    Raises:
        VbnCommonError: fewer than two views, mismatched lengths, non-finite
            poses, or rays (nearly) parallel.

    Example:
        >>> est = position_from_views([[0, 0, 0], [1, 0, 0]], [m_a, m_b])  # doctest: +SKIP
        >>> est.x, est.y, est.yaw, est.covariance  # doctest: +SKIP
    """
    poses = np.asarray(view_poses, dtype=float)
    if poses.ndim != 2 or poses.shape[1] != 3 or len(poses) != len(motions):
        raise VbnCommonError(f'view_poses must be (k, 3) with one row per motion, got '
                             f'shape {poses.shape} for {len(motions)} motions')
    if len(poses) < 2:
        raise VbnCommonError(f'the position needs at least two model views, got '
                             f'{len(poses)}')
    if not np.all(np.isfinite(poses)):
        raise VbnCommonError('view_poses must be finite')
    local = np.array([m.planar_direction for m in motions])                 # (k, 2)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    d = np.stack([c * local[:, 0] - s * local[:, 1], s * local[:, 0] + c * local[:, 1]], 1)
    normals = np.stack([-d[:, 1], d[:, 0]], axis=1)
    centres = poses[:, :2]
    cross = np.abs(d[:, None, 0] * d[None, :, 1] - d[:, None, 1] * d[None, :, 0])
    ray_angle = float(np.arcsin(np.clip(cross.max(), 0.0, 1.0)))
    if ray_angle < min_ray_angle:
        raise VbnCommonError(
            f'the rays from the {len(poses)} model views are parallel (largest angle '
            f'{ray_angle:.2e} rad < {min_ray_angle:.2e}): the position along them is '
            f'undetermined; add a model view off their line')
    var_phi = np.array([_variance(m.covariance[1, 1]) for m in motions])
    var_theta = np.array([_variance(m.covariance[0, 0]) for m in motions])
    weights = np.ones(len(poses))
    for _ in range(3):
        normal_matrix = np.einsum('k,ki,kj->ij', weights, normals, normals)
        rhs = np.einsum('k,ki,kj,kj->i', weights, normals, normals, centres)
        position = np.linalg.solve(normal_matrix, rhs)
        distance = np.maximum(np.linalg.norm(position - centres, axis=1), 1e-3)
        weights = 1.0 / (distance * distance * var_phi)
    normal_matrix = np.einsum('k,ki,kj->ij', weights, normals, normals)
    rhs = np.einsum('k,ki,kj,kj->i', weights, normals, normals, centres)
    position = np.linalg.solve(normal_matrix, rhs)
    offsets = np.einsum('ki,ki->k', normals, position - centres)              # signed, m
    cov_xy = np.linalg.inv(normal_matrix)
    if len(poses) > 2:
        chi2 = float(np.sum(weights * offsets * offsets)) / (len(poses) - 2)
        cov_xy = cov_xy * max(chi2, 1.0)
    in_front = bool(np.all(np.einsum('ki,ki->k', position - centres, d) > 0))
    if not in_front:
        _LOG.debug('a ray points away from the intersection of %d views', len(poses))
    headings = poses[:, 2] + np.array([m.theta for m in motions])
    w_theta = 1.0 / var_theta
    yaw = float(wrap_angle(math.atan2(float(np.sum(w_theta * np.sin(headings))),
                                      float(np.sum(w_theta * np.cos(headings))))))
    spread = wrap_angle(headings - yaw)
    var_yaw = 1.0 / float(np.sum(w_theta))
    if len(poses) > 1:
        chi2_yaw = float(np.sum(w_theta * spread * spread)) / (len(poses) - 1)
        var_yaw *= max(chi2_yaw, 1.0)
    covariance = np.zeros((3, 3))
    covariance[:2, :2] = cov_xy
    covariance[2, 2] = var_yaw
    return PoseEstimate(x=float(position[0]), y=float(position[1]), yaw=yaw,
                        covariance=covariance, ray_angle=ray_angle,
                        residual=float(math.sqrt(np.mean(offsets * offsets))),
                        n_views=len(poses), in_front=in_front)


def position_from_two_views(view_a_pose: np.ndarray, motion_a: RelativeMotion,
                            view_b_pose: np.ndarray, motion_b: RelativeMotion, *,
                            min_ray_angle: float = 1e-6) -> PoseEstimate:
    """Intersect the rays from a region's two model views (7.4).

    Args:
        view_a_pose: ``(3,)`` camera pose ``(x, y, yaw)`` of model view a in ``map``.
        motion_a: the motion from model view a to the current view.
        view_b_pose: ``(3,)`` camera pose of model view b in ``map``.
        motion_b: the motion from model view b to the current view.
        min_ray_angle: rays closer to parallel than this (radians) are refused.

    Returns:
        The current camera's pose in ``map`` (see :func:`position_from_views`).

    Raises:
        VbnCommonError: as :func:`position_from_views`.
    """
    a = np.asarray(view_a_pose, dtype=float).reshape(-1)
    b = np.asarray(view_b_pose, dtype=float).reshape(-1)
    if a.shape != (3,) or b.shape != (3,):
        raise VbnCommonError(f'model view poses must be (x, y, yaw), got '
                             f'{view_a_pose!r} and {view_b_pose!r}')
    return position_from_views(np.stack([a, b]), [motion_a, motion_b],
                               min_ray_angle=min_ray_angle)
