"""Model views and extra features of each region (thesis Sections 1.1, 7.2 and 7.4).

"Each region has associated with it two model views, i.e., two images acquired at two
extremes of the region, in which all k features that form the landmark corresponding
to the region are simultaneously visible" (7.2). The localizer intersects the two
translation directions from the model views' known poses (7.4); the intersection is
ill-conditioned when the robot stands near the line through the two views (nearly
parallel rays), so a third view off that line is kept where the region allows.

Selection, per region:

1. candidates: the images taken at the region's poses that show every landmark class;
2. the first two views: the candidate pair with the largest baseline (camera distance);
3. the third: the candidate farthest from the line through the first two, if that
   distance is at least ``min_third_offset`` metres (otherwise the region is a strip
   and a third view would not help).

Extra features (the k are the minimum, not the maximum): the classes that at least
``extra_min_fraction`` of the region's poses see, most widely seen first, at most
``max_extra``; they vote for the region and add rays to the pose solve. Each model
view stores the keypoints and descriptors of the landmark and extra classes it shows.

Representative descriptors (:func:`class_descriptors`): the thesis keeps one exemplar
per class and names keeping "a representative collection of the various appearances"
as the alternative (6.2.1); a feature's appearance changes across the region, so each
class keeps a few descriptors seen from poses far apart, for the localizer's voting.

Departures from the text: the thesis assumes one image per pose; with several headings
per pose (pinhole exploration) a model view is one image, so candidates are images,
not poses. A region without two candidate images keeps the one it has (the localizer
then needs a third view from a neighbour region or reports a larger covariance).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from landmark_db.database.model import ModelView
from vbn_common.features import ImageFeatures
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['ImageTable', 'ModelViewConfig', 'class_descriptors', 'extra_features',
           'select_model_views']


@dataclass(frozen=True)
class ModelViewConfig:
    """How many views and extra features a region keeps.

    Attributes:
        max_extra: At most this many extra classes per region.
        extra_min_fraction: An extra class is seen from at least this fraction of the
            region's poses.
        third_view: Keep a third view off the line of the first two where possible.
        min_third_offset: Least distance (m) of the third view from that line.
    """

    max_extra: int = 40
    extra_min_fraction: float = 0.8
    third_view: bool = True
    min_third_offset: float = 0.2

    def __post_init__(self) -> None:
        if self.max_extra < 0 or not 0 < self.extra_min_fraction <= 1 \
                or self.min_third_offset < 0:
            raise VisibilityBuilderError(f'invalid model view settings: {self}')


@dataclass(frozen=True)
class ImageTable:
    """Every exploration image with what model-view selection needs.

    Attributes:
        pose: (n_images,) int64 sampled pose of each image.
        stamp_ns: (n_images,) int64 header stamps.
        camera_xy: (n_images, 2) float64 camera position in ``map``.
        camera_yaw: (n_images,) float64 camera heading in ``map``.
        features: Per image, its SIFT features.
        labels: Per image, (n_i,) int64 class of each feature (-1: none), in the
            database's class numbering.
    """

    pose: np.ndarray
    stamp_ns: np.ndarray
    camera_xy: np.ndarray
    camera_yaw: np.ndarray
    features: Sequence[ImageFeatures]
    labels: Sequence[np.ndarray]

    def images_of_poses(self, poses: np.ndarray) -> np.ndarray:
        """Return the indices of the images taken at any of ``poses``."""
        return np.flatnonzero(np.isin(self.pose, poses))


def extra_features(visibility: sp.csr_matrix, poses: np.ndarray, landmark: np.ndarray,
                   config: ModelViewConfig = ModelViewConfig()) -> np.ndarray:
    """Return the region's extra classes, most widely seen first (ties: lower id).

    Args:
        visibility: (n_poses, n_classes) bool, the filtered visibility.
        poses: The region's poses.
        landmark: Its landmark classes (never extra).
        config: ``max_extra`` and ``extra_min_fraction``.
    """
    if config.max_extra == 0 or poses.size == 0:
        return np.zeros(0, np.int64)
    counts = np.asarray(visibility[poses].sum(axis=0)).ravel()
    counts[landmark] = 0
    need = int(np.ceil(config.extra_min_fraction * poses.size - 1e-9))
    chosen = np.flatnonzero(counts >= max(need, 1))
    order = np.lexsort((chosen, -counts[chosen]))
    return chosen[order][:config.max_extra].astype(np.int64)


def _view(table: ImageTable, image: int, classes: np.ndarray) -> ModelView:
    labels = table.labels[image]
    keep = np.flatnonzero(np.isin(labels, classes))
    feats = table.features[image]
    return ModelView(
        pose=int(table.pose[image]), image_stamp_ns=int(table.stamp_ns[image]),
        image_index=int(image), x=float(table.camera_xy[image, 0]),
        y=float(table.camera_xy[image, 1]), yaw=float(table.camera_yaw[image]),
        class_ids=labels[keep].astype(np.int64), keypoints=feats.keypoints[keep],
        descriptors=feats.descriptors[keep])


def select_model_views(table: ImageTable, poses: np.ndarray, landmark: np.ndarray,
                       extra: np.ndarray, config: ModelViewConfig = ModelViewConfig()
                       ) -> tuple[ModelView, ...]:
    """Pick the region's model views (see the module docstring).

    Raises:
        VisibilityBuilderError: No image of the region shows every landmark class
            (cannot happen for a region of a valid decomposition built from these
            labels).
    """
    images = table.images_of_poses(poses)
    shows_all = np.array([np.isin(landmark, table.labels[i]).all() for i in images], bool)
    candidates = images[shows_all]
    if candidates.size == 0:
        raise VisibilityBuilderError(
            f'no image of the region (poses {poses[:5].tolist()}...) shows all of its '
            f'landmark classes {landmark.tolist()}')
    classes = np.concatenate([landmark, extra])
    if candidates.size == 1:
        return (_view(table, int(candidates[0]), classes),)
    xy = table.camera_xy[candidates]
    # Secondary key: how many extra classes an image shows (a better view on ties).
    shown = np.array([np.isin(extra, table.labels[i]).sum() for i in candidates], float)
    dist = np.linalg.norm(xy[:, None, :] - xy[None, :, :], axis=2)
    score = dist + 1e-6 * (shown[:, None] + shown[None, :])
    a, b = np.unravel_index(int(np.argmax(score)), score.shape)
    chosen = [int(candidates[a]), int(candidates[b])]
    if config.third_view and candidates.size > 2 and dist[a, b] > 0:
        direction = (xy[b] - xy[a]) / dist[a, b]
        rel = xy - xy[a]
        offset = np.abs(rel[:, 0] * direction[1] - rel[:, 1] * direction[0])
        c = int(np.argmax(offset + 1e-6 * shown))
        if offset[c] >= config.min_third_offset:
            chosen.append(int(candidates[c]))
    return tuple(_view(table, i, classes) for i in chosen)


def class_descriptors(classes_of_features: np.ndarray, descriptors: np.ndarray,
                      positions: np.ndarray, n_classes: int, per_class: int
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Pick up to ``per_class`` representative descriptors of each class.

    A feature's appearance changes across the region that sees it, so the
    representatives come from poses far apart: farthest-point sampling on the
    positions the features were seen from, starting at the feature nearest the
    class's centroid.

    Args:
        classes_of_features: (N,) class of each candidate feature (>= 0).
        descriptors: (N, 128) uint8 their descriptors.
        positions: (N, 2) the position each was seen from.
        n_classes: Number of classes; every class must have a candidate.
        per_class: Representatives per class (at most).

    Returns:
        ``(descriptors, offsets)`` as :class:`~landmark_db.database.FeatureClasses`
        stores them.
    """
    order = np.argsort(classes_of_features, kind='stable')
    sorted_classes = classes_of_features[order]
    bounds = np.searchsorted(sorted_classes, np.arange(n_classes + 1))
    chosen: list[np.ndarray] = []
    offsets = np.zeros(n_classes + 1, np.int64)
    for c in range(n_classes):
        members = order[bounds[c]:bounds[c + 1]]
        if members.size == 0:
            raise VisibilityBuilderError(f'class {c} has no feature to describe it')
        pts = positions[members]
        first = int(np.argmin(np.linalg.norm(pts - pts.mean(axis=0), axis=1)))
        picked = [first]
        gap = np.linalg.norm(pts - pts[first], axis=1)
        while len(picked) < min(per_class, members.size):
            nxt = int(np.argmax(gap))
            if gap[nxt] <= 0:
                break
            picked.append(nxt)
            gap = np.minimum(gap, np.linalg.norm(pts - pts[nxt], axis=1))
        chosen.append(members[picked])
        offsets[c + 1] = offsets[c] + len(picked)
    rows = np.concatenate(chosen) if chosen else np.zeros(0, np.int64)
    return descriptors[rows], offsets
