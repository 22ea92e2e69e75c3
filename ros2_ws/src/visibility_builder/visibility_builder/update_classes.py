"""New feature classes from a re-exploration: what the changed world shows that was not there.

A poster hung where there was bare wall, a cupboard's printed side: features the
exploration never saw. After :func:`~visibility_builder.db_update.label_features` has
given the update images' features the database's classes they show, the features left
without one go through the build's own steps on the updated poses alone:
correspondence classes (Algorithm 6.3, :mod:`.classes`) over the pose graph between
those poses, their geometric verification (:mod:`.verification`), the filters of
Section 6.2.2 (:mod:`.filters`), a scene point per class (:mod:`.scene_points`) and
representative descriptors (:func:`~visibility_builder.model_views.class_descriptors`).
The surviving classes are appended to the database's, so every old class id keeps its
meaning.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.database import FeatureClasses, LandmarkDatabase, ScenePoints
from landmark_db.database.points import SEEN_MARGIN_M
from vbn_common.features import ImageFeatures
from vbn_common.geometry.frames import world_points_to_camera
from visibility_builder.build import BuildConfig
from visibility_builder.classes import correspondence_classes
from visibility_builder.filters import retain_good_features
from visibility_builder.model_views import class_descriptors
from visibility_builder.point_patches import patch_sources
from visibility_builder.scene_points import labels_by_image, scene_points
from visibility_builder.verification import verify_classes

__all__ = ['NewClasses', 'looked_at', 'merge_classes', 'merge_points', 'new_classes',
           'select_points']


@dataclass(frozen=True)
class NewClasses:
    """Classes found among the update's unlabelled features.

    Attributes:
        n_classes: How many (ids ``0 .. n - 1``, before the database's offset).
        visibility: ``(n_updated, n_classes)`` bool CSR, by updated pose.
        labels: Per update image (the order given), ``(n_i,)`` the new class of each
            of its features (-1: none), in the image's full feature order.
        descriptors: Representative descriptors, as :class:`FeatureClasses` keeps them.
        offsets: ``(n_classes + 1,)`` their offsets.
        points: The scene points of the update's images: the classes' (class ids
            ``0 .. n - 1``) and the others (class -1).
    """

    n_classes: int
    visibility: sp.csr_matrix
    labels: list[np.ndarray]
    descriptors: np.ndarray
    offsets: np.ndarray
    points: ScenePoints


def _subset(features: ImageFeatures, keep: np.ndarray) -> ImageFeatures:
    return ImageFeatures(keypoints=features.keypoints[keep], sizes=features.sizes[keep],
                         angles=features.angles[keep], responses=features.responses[keep],
                         descriptors=features.descriptors[keep])


def new_classes(database: LandmarkDatabase, updated: np.ndarray, images: Sequence[int],
                features: Sequence[ImageFeatures], labels: Sequence[np.ndarray],
                pose_of: np.ndarray, cameras: np.ndarray, frames: Sequence[Any],
                camera: Any, config: BuildConfig, workers: int) -> NewClasses:
    """Group the unlabelled features of the update images into new classes.

    Args:
        database: The database being updated (its pose graph and lattice).
        updated: The updated poses (sorted).
        images: The update images used (indices into ``frames``).
        features: Their SIFT features, in the order of ``images``.
        labels: Their database classes (-1: none), in the order of ``images``.
        pose_of: ``(n_frames,)`` the database pose of each frame.
        cameras: ``(n_frames, 3)`` camera poses.
        frames: The update's frames (for the points' patches).
        camera: The camera model.
        config: The database's build settings.
        workers: Processes for the class matching.
    """
    renumber = np.full(database.n_poses, -1, np.int64)   # updated pose -> its row here
    renumber[updated] = np.arange(len(updated))
    free = [np.flatnonzero(np.asarray(lab) < 0) for lab in labels]
    sub = [_subset(f, keep) for f, keep in zip(features, free, strict=True)]
    frames_of_pose: list[list[int]] = [[] for _ in updated]
    for m, i in enumerate(images):
        frames_of_pose[renumber[pose_of[i]]].append(m)
    sub_edges = renumber[database.poses.edges]
    sub_edges = sub_edges[(sub_edges >= 0).all(axis=1)].reshape(-1, 2)

    def per_pose(get: Any) -> list[np.ndarray]:
        return [np.concatenate([get(m) for m in members]) for members in frames_of_pose]

    empty = NewClasses(0, sp.csr_matrix((len(updated), 0), dtype=bool),
                       [np.full(len(f), -1, np.int64) for f in features],
                       np.zeros((0, 128), np.uint8), np.zeros(1, np.int64), ScenePoints.empty())
    if sum(len(s) for s in sub) == 0 or sub_edges.size == 0:
        return empty
    classes = correspondence_classes(per_pose(lambda m: sub[m].descriptors), sub_edges,
                                     replace(config.classes, workers=workers))
    classes = verify_classes(
        classes, per_pose(lambda m: sub[m].keypoints), per_pose(lambda m: sub[m].sizes),
        per_pose(lambda m: np.repeat(cameras[images[m]][None], len(sub[m]), axis=0)),
        camera, config.verify)
    if classes.n_classes == 0:
        return empty
    headings = int(database.info.parameters.get('pose_headings', 1) or 1)
    grid = database.poses.grid[updated] if headings == 1 else \
        np.full((len(updated), 2), -1, np.int64)
    filtered = retain_good_features(classes.visibility, grid, sub_edges, config.filters)
    kept = np.asarray(filtered.kept_classes, np.int64)
    if kept.size == 0:
        return empty
    visibility = filtered.visibility.tocsr().astype(bool)
    verified = labels_by_image(frames_of_pose, classes.labels, [len(s) for s in sub])
    remap = np.full(classes.n_classes, -1, np.int64)
    remap[kept] = np.arange(kept.size)
    image_pose = renumber[pose_of[np.asarray(images, np.int64)]]
    decode, usable = patch_sources([frames[i] for i in images])
    points = scene_points(verified, sub, cameras[list(images)], camera, kept, config.points,
                          decode, usable)
    out_labels, cls_list, desc_list, pos_list = [], [], [], []
    for m, (lab, keep) in enumerate(zip(verified, free, strict=True)):
        mapped = np.where(lab >= 0, remap[np.maximum(lab, 0)], -1)
        full = np.full(len(features[m]), -1, np.int64)
        full[keep] = mapped
        out_labels.append(full)
        valid = np.flatnonzero(mapped >= 0)
        valid = valid[np.asarray(visibility[image_pose[m], mapped[valid]].todense()).ravel()] \
            if valid.size else valid
        cls_list.append(mapped[valid])
        desc_list.append(sub[m].descriptors[valid])
        pos_list.append(np.repeat(cameras[images[m]][None, :2], valid.size, axis=0))
    descriptors, offsets = class_descriptors(
        np.concatenate(cls_list), np.concatenate(desc_list), np.concatenate(pos_list),
        kept.size, config.descriptors_per_class)
    return NewClasses(int(kept.size), visibility, out_labels, descriptors, offsets, points)


def select_points(points: ScenePoints, rows: np.ndarray) -> ScenePoints:
    """Return the points of ``rows`` (a mask or indices)."""
    def part(value: np.ndarray | None) -> np.ndarray | None:
        return None if value is None else value[rows]

    return ScenePoints(xyz=points.xyz[rows], class_ids=points.class_ids[rows],
                       descriptors=points.descriptors[rows], views=points.views[rows],
                       seen_from=part(points.seen_from), patches=part(points.patches),
                       patch_axes=part(points.patch_axes))


def merge_classes(old: FeatureClasses, visibility: sp.csr_matrix, new: NewClasses,
                  updated: np.ndarray) -> FeatureClasses:
    """Return ``old``'s classes with ``new``'s appended; ``visibility`` for the old columns."""
    n_poses = visibility.shape[0]
    rows = sp.csr_matrix((np.ones(new.visibility.nnz, bool),
                          (np.asarray(updated)[new.visibility.tocoo().row],
                           new.visibility.tocoo().col)), shape=(n_poses, new.n_classes))
    return FeatureClasses(
        np.concatenate([old.descriptors, new.descriptors]),
        np.concatenate([old.offsets, old.offsets[-1] + new.offsets[1:]]),
        sp.hstack([visibility, rows], format='csr').astype(bool))


def looked_at(points: ScenePoints, cameras: np.ndarray, camera: Any) -> np.ndarray:
    """Return ``(n,)`` bool: the points an update image shows, from near where they were seen.

    A point falls inside the image of one of ``cameras`` (``(m, 3)`` camera poses) taken
    within its ``seen_from`` spread plus ``SEEN_MARGIN_M``. The update's own points
    replace those: whatever the old ones showed is either seen again (a new point at the
    same place) or gone (a poster taken down, a cupboard in front of it). A file that
    does not say where its points were seen from has none looked at (a panoramic image
    shows every point of the map).
    """
    n = points.n_points
    shown = np.zeros(n, bool)
    if n == 0 or len(cameras) == 0 or not points.has_seen_from:
        return shown
    seen = np.asarray(points.seen_from, float)
    for pose in np.asarray(cameras, float).reshape(-1, 3):
        near = np.hypot(seen[:, 0] - pose[0], seen[:, 1] - pose[1]) <= seen[:, 2] + \
            SEEN_MARGIN_M
        rows = np.flatnonzero(near & ~shown)
        if rows.size:
            _, inside = camera.project(world_points_to_camera(pose, 0.0, points.xyz[rows]))
            shown[rows[inside]] = True
    return shown


def merge_points(old: ScenePoints, new: ScenePoints, offset: int) -> ScenePoints:
    """Return ``old``'s points with ``new``'s appended, their classes shifted by ``offset``."""
    if new.n_points == 0:
        return old

    def both(a: np.ndarray | None, b: np.ndarray | None) -> np.ndarray | None:
        if a is None or b is None or a.shape[1:] != b.shape[1:]:
            return None
        return np.concatenate([a, b])

    patches = both(old.patches, new.patches)
    return ScenePoints(
        xyz=np.concatenate([old.xyz, new.xyz]),
        class_ids=np.concatenate([old.class_ids, np.where(new.class_ids >= 0,
                                                          new.class_ids + offset, -1)]),
        descriptors=np.concatenate([old.descriptors, new.descriptors]),
        views=np.concatenate([old.views, new.views]),
        seen_from=both(old.seen_from, new.seen_from),
        patches=patches, patch_axes=None if patches is None else both(old.patch_axes,
                                                                       new.patch_axes))
