"""Purity of feature classes, measured with a rendered scene's ground truth (evaluation).

A class of Algorithm 6.3 (:mod:`visibility_builder.classes`) should hold the images of
one scene point. On a rendered bag the renderer knows the wall point behind every
pixel (:meth:`~vbn_worlds.render.renderer.Renderer.pixel_to_wall_point`), so
a class can be checked: it is *pure* when one scene point explains all its members.

Why pixels and not metres. A spread of wall points in metres misjudges features seen
at grazing incidence: from 25 cm beside a wall, one pixel of keypoint jitter moves the
wall point by 30 cm four metres along it. The test is therefore in the image, where
SIFT localises keypoints: each member's wall point is projected into every other
member's view, and the class is pure when some member's point reprojects within
tolerance of every member's keypoint (the min over candidate points of the max
reprojection error). A member's tolerance is ``max(tolerance_px, size_fraction *
size)``: a SIFT keypoint's position is only as precise as its scale (measured on the
room bag: mutual matches of adjacent poses with keypoints 16 to 32 px wide reproject
within 8 px for 90 % of them, 4 to 8 px wide ones within 1 px), so by default the true
point must fall within the keypoint's radius, and never further than 4 px for small
keypoints. Columns wrap around for the panorama. Keypoints on the floor or
ceiling just beside a wall edge (SIFT blobs straddling the skirting) get the wall point
of their column with the height clamped to the wall, see :func:`keypoint_wall_points`.

This module is for evaluation and tests; the builder does not use it.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import logging

import numpy as np

from vbn_common.geometry.camera import CameraModel
from vbn_common.geometry.frames import world_points_to_camera
from vbn_worlds.render.renderer import Renderer
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['PurityReport', 'class_purity', 'keypoint_wall_points']

logger = logging.getLogger(__name__)


@dataclass
class PurityReport:
    """Purity of the classes seen from at least ``min_poses`` poses.

    Attributes:
        n_classes: classes evaluated.
        n_impure: classes no single scene point explains within the tolerance.
        impure_fraction: ``n_impure / n_classes`` (0 when there are none).
        error: ``(n_classes,)`` per class, the smallest over member points of the
            largest reprojection error over members, in units of each member's
            tolerance (a class is impure when it exceeds 1).
        class_ids: ``(n_classes,)`` the evaluated class ids, aligned with ``error_px``.
        impure_ids: ids of the impure classes.
        tolerance_px: the smallest tolerance, pixels.
        size_fraction: tolerance per pixel of keypoint size.
    """

    n_classes: int
    n_impure: int
    impure_fraction: float
    error: np.ndarray
    class_ids: np.ndarray
    impure_ids: np.ndarray
    tolerance_px: float
    size_fraction: float


def keypoint_wall_points(renderer: Renderer, pose: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Return the ``map`` wall points behind keypoints, floor/ceiling clamped to the wall.

    Args:
        renderer: renderer of the scene the image came from.
        pose: ``(x, y, yaw)`` of ``base_link`` when the image was taken.
        uv: ``(n, 2)`` keypoint pixel coordinates.

    Returns:
        ``(n, 3)`` float64 points; NaN only where the column hits no wall.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    points = renderer.pixel_to_wall_point(np.asarray(pose, float), uv[:, 0], uv[:, 1])
    off = ~np.isfinite(points).all(axis=1)
    if off.any():
        # The wall column at the horizon row, with the height of the wall edge.
        column = renderer.pixel_to_wall_point(
            np.asarray(pose, float), uv[off, 0],
            np.full(int(off.sum()), renderer.camera.horizon_row))
        below = uv[off, 1] > renderer.camera.horizon_row
        column[:, 2] = np.where(below, 0.0, renderer.scene.wall_height)
        points[off] = column
    return points


def class_purity(labels: Sequence[np.ndarray], keypoints: Sequence[np.ndarray],
                 wall_points: Sequence[np.ndarray], poses: np.ndarray, camera: CameraModel,
                 camera_height: float, keypoint_sizes: Sequence[np.ndarray] | None = None,
                 tolerance_px: float = 4.0, size_fraction: float = 0.5,
                 min_poses: int = 2) -> PurityReport:
    """Check every class against the scene points behind its members' keypoints.

    Args:
        labels: per pose, ``(n_i,)`` class id per feature, -1 for excluded features
            (:attr:`~visibility_builder.classes.ClassResult.labels`).
        keypoints: per pose, ``(n_i, 2)`` keypoint pixel coordinates (one image per
            pose: the panorama).
        wall_points: per pose, ``(n_i, 3)`` ground-truth ``map`` points
            (:func:`keypoint_wall_points`).
        poses: ``(n_poses, 3)`` ``(x, y, yaw)`` of each pose.
        camera: the camera model of the images.
        camera_height: camera height above the floor, metres.
        keypoint_sizes: per pose, ``(n_i,)`` keypoint diameters (OpenCV ``size``),
            pixels; ``None``: tolerance ``tolerance_px`` for every member.
        tolerance_px: smallest reprojection tolerance, pixels.
        size_fraction: a member's tolerance grows to this fraction of its size.
        min_poses: evaluate classes with at least this many members.

    Returns:
        The :class:`PurityReport`.

    Raises:
        VisibilityBuilderError: when the per-pose arrays do not line up.
    """
    n_poses = len(labels)
    if not (len(keypoints) == len(wall_points) == n_poses == len(poses)):
        raise VisibilityBuilderError(
            f'purity needs one labels, keypoints, wall_points and pose per pose, got '
            f'{len(labels)}, {len(keypoints)}, {len(wall_points)}, {len(poses)}')
    lab = np.concatenate([np.asarray(x, np.int64).ravel() for x in labels])
    uv = np.concatenate([np.asarray(x, float).reshape(-1, 2) for x in keypoints])
    pts = np.concatenate([np.asarray(x, float).reshape(-1, 3) for x in wall_points])
    if keypoint_sizes is None:
        size = np.zeros(len(lab))
    else:
        size = np.concatenate([np.asarray(x, float).ravel() for x in keypoint_sizes])
        if len(size) != len(lab):
            raise VisibilityBuilderError(
                f'keypoint_sizes ({len(size)}) and labels ({len(lab)}) differ in length')
    tol = np.maximum(float(tolerance_px), float(size_fraction) * size)
    if not (len(lab) == len(uv) == len(pts)):
        raise VisibilityBuilderError(
            f'labels ({len(lab)}), keypoints ({len(uv)}) and wall points ({len(pts)}) '
            'differ in length')
    pose_of = np.repeat(np.arange(n_poses), [len(x) for x in labels])
    keep = lab >= 0
    lab, uv, pts, pose_of, tol = lab[keep], uv[keep], pts[keep], pose_of[keep], tol[keep]
    order = np.argsort(lab, kind='stable')
    lab, uv, pts, pose_of, tol = lab[order], uv[order], pts[order], pose_of[order], tol[order]
    if len(lab) == 0:
        return PurityReport(0, 0, 0.0, np.zeros(0), np.zeros(0, np.int64),
                            np.zeros(0, np.int64), float(tolerance_px), float(size_fraction))
    ids, starts, sizes = np.unique(lab, return_index=True, return_counts=True)
    chosen = sizes >= min_poses
    poses = np.asarray(poses, float)
    errors = np.empty(int(chosen.sum()))
    for k, (start, size) in enumerate(zip(starts[chosen], sizes[chosen])):
        members = slice(start, start + size)
        errors[k] = _class_error(uv[members], tol[members], pts[members],
                                 poses[pose_of[members]], camera, camera_height)
    class_ids = ids[chosen]
    impure = ~(errors <= 1.0)
    n = len(class_ids)
    return PurityReport(n, int(impure.sum()), float(impure.mean()) if n else 0.0, errors,
                        class_ids, class_ids[impure], float(tolerance_px), float(size_fraction))


def _class_error(uv: np.ndarray, tol: np.ndarray, points: np.ndarray, poses: np.ndarray,
                 camera: CameraModel, camera_height: float) -> float:
    """Return min over member points X_i of max over j of |proj_j(X_i) - uv_j| / tol_j."""
    candidates = points[np.isfinite(points).all(axis=1)]
    if len(candidates) == 0:
        return float('inf')
    worst = np.zeros(len(candidates))
    for j in range(len(uv)):
        cam = world_points_to_camera(poses[j], camera_height, candidates)
        proj, valid = camera.project(cam)
        du = np.abs(proj[:, 0] - uv[j, 0])
        if camera.kind == 'panoramic':
            du = np.minimum(du, camera.width - du)
        err = np.hypot(du, proj[:, 1] - uv[j, 1])
        err[~valid] = np.inf
        np.maximum(worst, err / tol[j], out=worst)
    return float(worst.min())
