"""Geometric verification of correspondence classes: one scene point per class.

Problem. Algorithm 6.3 (:mod:`visibility_builder.classes`) groups image features by
their descriptors alone. A class is meant to hold the images of one scene point, but
a chain of symmetric, unique nearest neighbours can join two points (repeated
texture, a keypoint sliding along an edge, a blob whose centre drifts with the
viewpoint), and the descriptor tests of Figure 6.3 cannot see it
(``docs/classes.md``). The builder knows where every image was taken (Section 6.1:
the exploration images' poses), so a class can be checked the way structure from
motion checks a feature track: the rays of its members must meet in one point.

Method, per class with at least two members:

1. every member gives a ray from its camera centre (the camera's ``(x, y)`` in
   ``map`` at the camera's height, which is the same for every image of a planar
   robot, so heights are relative to it) through its keypoint
   (:meth:`CameraModel.unproject`, turned into ``map`` by the camera heading);
2. the point nearest to all rays in the least-squares sense is found (one 3 x 3
   solve), and is projected back into every member's image;
3. a member is an outlier when its reprojection error exceeds its tolerance
   ``max(tolerance_px, size_fraction * keypoint size)`` (a keypoint is only as
   precise as its scale); the worst outlier is removed and 2-3 repeat, until every
   member agrees;
4. if more than ``max_outlier_fraction`` of the members were removed, or fewer than
   two remain, the whole class is excluded (Figure 6.3's spirit: a class that
   mixes scene points is not distinctive); otherwise only the removed members are
   (their features become unclassified, as an ambiguous feature does in 6.3).

A point behind a pinhole camera or outside its image counts as an outlier for that
member. Complexity: O(sum of m^2) for classes of m members (in practice m <= 100).

This step is not in the thesis, which checks correspondences by descriptors only
and reports one wrongly classified feature in 897 classes after a visual check
(Section 6.2.1). It is a departure with a reason: purity measured against the
renderer's ground truth (:mod:`vbn_bench.purity`).

Reference: thesis Sections 6.1 and 6.2.1; Schoenberger and Frahm, Structure-from-Motion
Revisited (CVPR 2016), for track filtering by reprojection error.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import logging
import math
import time

import numpy as np
import scipy.sparse as sp

from vbn_common.geometry.camera import CameraModel
from visibility_builder.classes import ClassResult
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['VerifyConfig', 'map_rays', 'reprojection_error', 'verify_classes']

logger = logging.getLogger(__name__)


@dataclass(frozen=True)
class VerifyConfig:
    """Parameters of the geometric verification of classes.

    Attributes:
        enabled: run the verification (False: classes pass unchanged).
        tolerance_px: smallest reprojection tolerance of a member, pixels.
        size_fraction: a member's tolerance grows to this fraction of its keypoint
            size (diameter), pixels per pixel.
        max_outlier_fraction: a class losing more than this fraction of its members
            as outliers is excluded whole.
    """

    enabled: bool = True
    tolerance_px: float = 2.0
    size_fraction: float = 0.2
    max_outlier_fraction: float = 0.1

    def __post_init__(self) -> None:
        for name in ('tolerance_px', 'size_fraction'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise VisibilityBuilderError(
                    f'{name} must be a non-negative number, got {value!r}')
        if self.tolerance_px <= 0 and self.size_fraction <= 0:
            raise VisibilityBuilderError('tolerance_px and size_fraction cannot both be 0')
        if not (isinstance(self.max_outlier_fraction, (int, float))
                and 0 <= self.max_outlier_fraction <= 1):
            raise VisibilityBuilderError(
                f'max_outlier_fraction must be in [0, 1], got {self.max_outlier_fraction!r}')


def verify_classes(classes: ClassResult, keypoints: Sequence[np.ndarray],
                   sizes: Sequence[np.ndarray], camera_poses: Sequence[np.ndarray],
                   camera: CameraModel, config: VerifyConfig | None = None) -> ClassResult:
    """Remove the members, or whole classes, whose rays do not meet in one point.

    Args:
        classes: the classes of :func:`~visibility_builder.classes.correspondence_classes`.
        keypoints: per pose, ``(n_i, 2)`` pixel coordinates of its features, in the
            order of ``classes.labels[i]`` (the pose's images concatenated).
        sizes: per pose, ``(n_i,)`` keypoint diameters, pixels.
        camera_poses: per pose, ``(n_i, 3)`` ``(x, y, heading)`` in ``map`` of the camera
            that saw each feature (the camera's optical axis heading), or ``(3,)`` when
            one camera pose holds for the whole pose.
        camera: the camera model of the images.
        config: the tolerances; defaults of :class:`VerifyConfig`.

    Returns:
        A new :class:`ClassResult`: rejected features labelled -1, excluded classes
        removed and the rest renumbered ``0 .. n - 1`` in their old order. ``stats``
        adds ``verified`` (classes checked), ``outlier_features``,
        ``excluded_geometry`` and ``verify_seconds``.

    Raises:
        VisibilityBuilderError: when the per-pose arrays do not match the labels.
    """
    config = config if config is not None else VerifyConfig()
    start = time.perf_counter()
    n_poses = len(classes.labels)
    if not (len(keypoints) == len(sizes) == len(camera_poses) == n_poses):
        raise VisibilityBuilderError(
            f'verification needs keypoints, sizes and camera poses for each of the '
            f'{n_poses} poses, got {len(keypoints)}, {len(sizes)}, {len(camera_poses)}')
    counts = np.array([len(lab) for lab in classes.labels], dtype=np.int64)
    labels = np.concatenate(classes.labels) if n_poses else np.zeros(0, np.int64)
    uv = _stack(keypoints, counts, 2, 'keypoints')
    size = _stack(sizes, counts, 1, 'sizes')[:, 0]
    pose = np.concatenate([
        np.broadcast_to(np.asarray(p, float).reshape(-1, 3), (n, 3)) if np.size(p) == 3
        else np.asarray(p, float).reshape(n, 3)
        for p, n in zip(camera_poses, counts.tolist())]) if n_poses else np.zeros((0, 3))
    if len(pose) != len(labels):
        raise VisibilityBuilderError(
            f'camera_poses give {len(pose)} features, the labels {len(labels)}')
    if not config.enabled:
        return classes

    tol = np.maximum(config.tolerance_px, config.size_fraction * size)
    members = np.flatnonzero(labels >= 0)
    order = members[np.argsort(labels[members], kind='stable')]
    ids, starts, lengths = np.unique(labels[order], return_index=True, return_counts=True)
    # World ray of every classified feature: the optical-frame ray turned by the heading.
    rays = np.zeros((len(labels), 3))
    if order.size:
        rays[order] = map_rays(camera.unproject(uv[order]), pose[order, 2])
    keep_feature = np.ones(len(labels), dtype=bool)
    keep_class = np.ones(classes.n_classes, dtype=bool)
    verified = outliers = 0
    for cid, first, length in zip(ids.tolist(), starts.tolist(), lengths.tolist()):
        if length < 2:
            continue
        verified += 1
        idx = order[first:first + length]
        good = _consistent_members(rays[idx], pose[idx], uv[idx], tol[idx], camera)
        n_out = int(length - good.sum())
        if n_out == 0:
            continue
        if n_out > config.max_outlier_fraction * length or good.sum() < 2:
            keep_class[cid] = False
            keep_feature[idx] = False
        else:
            keep_feature[idx[~good]] = False
            outliers += n_out

    new_id = np.full(classes.n_classes, -1, dtype=np.int64)
    n_classes = int(keep_class.sum())
    new_id[keep_class] = np.arange(n_classes)
    flat = np.where((labels >= 0) & keep_feature, new_id[np.maximum(labels, 0)], -1)
    pose_of = np.repeat(np.arange(n_poses, dtype=np.int64), counts)
    kept = flat >= 0
    visibility = sp.csr_matrix(
        (np.ones(int(kept.sum()), dtype=bool), (pose_of[kept], flat[kept])),
        shape=(n_poses, n_classes))
    visibility.sum_duplicates()
    visibility.sort_indices()
    offsets = np.concatenate([[0], np.cumsum(counts)])
    new_labels = [flat[offsets[i]:offsets[i + 1]].copy() for i in range(n_poses)]
    stats = dict(classes.stats)
    stats.update({
        'verified': verified,
        'outlier_features': outliers,
        'excluded_geometry': int(classes.n_classes - n_classes),
        'classes': n_classes,
        'features_kept': int(kept.sum()),
        'verify_seconds': round(time.perf_counter() - start, 3),
    })
    logger.info('geometric verification (%s): %d classes checked, %d outlier features '
                'removed, %d classes excluded', config, verified, outliers,
                classes.n_classes - n_classes)
    return ClassResult(new_labels, n_classes, visibility, stats)


def _consistent_members(rays: np.ndarray, pose: np.ndarray, uv: np.ndarray, tol: np.ndarray,
                        camera: CameraModel) -> np.ndarray:
    """Members left after removing the worst reprojection outlier until all agree."""
    good = np.ones(len(rays), dtype=bool)
    centres = np.column_stack([pose[:, :2], np.zeros(len(pose))])
    while good.sum() >= 2:
        point = _nearest_point(rays[good], centres[good])
        error = reprojection_error(point, pose, uv, camera) / tol
        error[~good] = -np.inf
        worst = int(np.argmax(error))
        if error[worst] <= 1.0:
            break
        good[worst] = False
    return good


def _nearest_point(rays: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Least-squares point nearest to rays ``centre + t * ray`` (unit rays)."""
    # sum_i (I - d_i d_i^T) x = sum_i (I - d_i d_i^T) c_i
    proj = np.eye(3)[None] - rays[:, :, None] * rays[:, None, :]
    a = proj.sum(axis=0)
    b = np.einsum('nij,nj->i', proj, centres)
    # Near-parallel rays (a distant point) leave a nearly singular system; the small
    # ridge keeps the point finite without moving a well-defined one.
    return np.linalg.solve(a + 1e-9 * np.eye(3), b)


def map_rays(optical: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """(n, 3) ``map`` rays (z up) of levelled optical rays (x right, y down, z forward)."""
    c, s = np.cos(heading), np.sin(heading)
    forward, left, up = optical[:, 2], -optical[:, 0], -optical[:, 1]
    return np.column_stack([c * forward - s * left, s * forward + c * left, up])


def reprojection_error(points: np.ndarray, pose: np.ndarray, uv: np.ndarray,
                       camera: CameraModel) -> np.ndarray:
    """Pixel distance between each member's keypoint and its point's projection.

    Args:
        points: ``(3,)`` one point for every member, or ``(n, 3)`` one each.
        pose: ``(n, 3)`` the members' camera ``(x, y, heading)``.
        uv: ``(n, 2)`` their keypoints.
        camera: the camera as mounted.

    Returns:
        ``(n,)`` errors, inf where the point does not project (behind, not finite).
    """
    points = np.broadcast_to(np.asarray(points, float), (len(pose), 3))
    dx = points[:, 0] - pose[:, 0]
    dy = points[:, 1] - pose[:, 1]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    forward = c * dx + s * dy
    left = -s * dx + c * dy
    local = np.column_stack([-left, -points[:, 2], forward])
    finite = np.all(np.isfinite(local), axis=1)
    error = np.full(len(pose), np.inf)
    if finite.any():
        proj, valid = camera.project(local[finite])
        du = np.abs(proj[:, 0] - uv[finite, 0])
        if camera.kind == 'panoramic':
            du = np.minimum(du, camera.width - du)
        e = np.hypot(du, proj[:, 1] - uv[finite, 1])
        e[~valid | ~np.isfinite(e)] = np.inf
        error[finite] = e
    return error


def _stack(arrays: Sequence[np.ndarray], counts: np.ndarray, width: int,
           name: str) -> np.ndarray:
    out = []
    for i, (arr, n) in enumerate(zip(arrays, counts.tolist())):
        a = np.asarray(arr, dtype=float).reshape(-1, width)
        if len(a) != n:
            raise VisibilityBuilderError(
                f'{name} of pose {i} hold {len(a)} features, its labels {n}')
        out.append(a)
    return np.concatenate(out) if out else np.zeros((0, width))
