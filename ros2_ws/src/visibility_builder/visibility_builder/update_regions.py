"""The regions a database update adds, and the world it decomposes.

Part of ``vbn db-update`` (:mod:`.db_update`): after the regions an update leaves
intact are kept, the poses they no longer serve get regions of a new decomposition
(Chapter 5) of the updated world, each with model views (Section 7.2) from the update's
images or from the model views kept elsewhere.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from landmark_db.database import LandmarkDatabase, ModelView, RegionRecord
from landmark_db.decomposition import Decomposition, decompose, service
from landmark_db.decomposition.overlap import covered_poses, neighbourhood_matrix
from landmark_db.decomposition.set_cover import solve_set_cover
from landmark_db.errors import LandmarkDbError
from landmark_db.world import WorldInstance
from vbn_common.features import ImageFeatures
from visibility_builder.build_config import BuildConfig
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.model_views import ImageTable, extra_features, select_model_views

__all__ = ['image_table', 'new_regions', 'replace_visibility']


def replace_visibility(database: LandmarkDatabase, visibility: sp.csr_matrix,
                       blocked: np.ndarray | None = None) -> WorldInstance:
    """Return the database's world instance with another visibility.

    ``blocked`` poses (furniture stands there now) leave the pose graph: no robot
    stands there, so no region's neighbourhood reaches through them (a pose that sees
    nothing in a neighbourhood would leave no feature common to it).
    """
    world = database.to_world_instance()
    edges = database.poses.edges
    if blocked is not None and len(blocked):
        edges = edges[~np.isin(edges, blocked).any(axis=1)]
    return WorldInstance.from_visibility(
        world.poses, edges, visibility,
        feature_ids=np.arange(visibility.shape[1], dtype=np.int64),
        spacing=database.poses.spacing, name=world.name)


def image_table(database: LandmarkDatabase, updated: np.ndarray,
                 features: dict[int, ImageFeatures], labels: dict[int, np.ndarray],
                 pose_of: np.ndarray, cameras: np.ndarray, frames: Any) -> ImageTable:
    """Return the images model views may come from: the update's, old views elsewhere."""
    pose, stamp, xy, yaw, feats, labs = [], [], [], [], [], []
    for i in sorted(features):
        pose.append(int(pose_of[i]))
        stamp.append(int(frames[i].stamp_ns))
        xy.append(cameras[i, :2])
        yaw.append(float(cameras[i, 2]))
        feats.append(features[i])
        labs.append(labels[i])
    seen: set[tuple[int, int]] = set()
    for region in database.regions:
        for view in region.model_views:
            key = (view.image_index, view.image_stamp_ns)
            if view.pose in updated or key in seen:
                continue
            seen.add(key)
            pose.append(view.pose)
            stamp.append(view.image_stamp_ns)
            xy.append(np.array([view.x, view.y]))
            yaw.append(view.yaw)
            feats.append(_view_features(view))
            labs.append(view.class_ids)
    return ImageTable(pose=np.asarray(pose, np.int64), stamp_ns=np.asarray(stamp, np.int64),
                      camera_xy=np.asarray(xy, float).reshape(-1, 2),
                      camera_yaw=np.asarray(yaw, float), features=feats, labels=labs)


def _view_features(view: ModelView) -> ImageFeatures:
    m = len(view)
    zeros = np.zeros(m, np.float32)
    return ImageFeatures(keypoints=view.keypoints, sizes=zeros, angles=zeros,
                         responses=zeros, descriptors=view.descriptors)


def new_regions(database: LandmarkDatabase, visibility: sp.csr_matrix,
                 blocked: np.ndarray, needed: np.ndarray, config: BuildConfig,
                 table: ImageTable) -> list[RegionRecord]:
    """Regions of a new decomposition that serve ``needed``, fewest first, with views.

    A region of the new decomposition may lie where neither the update's images nor the
    kept model views show its whole landmark (poses away from the update keep their old
    visibility, the old views list only their own regions' features): it is left out
    when other candidates serve its poses. When none does, the landmark features that
    the region's image showing most of it lacks (all of them, if no image was taken
    there) are hidden from the decomposition at the region's poses and it is drawn
    again, at most :data:`_REDRAWS` times; a needed pose that only such a region could
    serve refuses the update.
    """
    dc = config.decomposition
    usable = visibility
    world = replace_visibility(database, visibility, blocked)
    coverable = np.intersect1d(needed, service(world, [], dc.k, dc.rho).unserved)
    blind = None
    for _ in range(_REDRAWS + 1):
        try:
            decomposition = decompose(replace_visibility(database, usable, blocked),
                                      dc.algorithm, dc.k, dc.rho, dc.sigma, rng=dc.seed)
        except LandmarkDbError as error:
            raise VisibilityBuilderError(f'the updated world cannot be decomposed: {error}'
                                         ) from error
        regions, found = _regions_with_views(decomposition, database, visibility, blocked,
                                             needed, config, table)
        if found is None:
            left = service(world, [r.poses for r in regions], dc.k, dc.rho).unserved
            if blind is None or not np.isin(coverable, left).any():
                return regions
            break  # (hiding features left a pose the real world serves unserved)
        blind = found
        poses, landmark = blind
        # (Model views come from the region's own images: judge only those.)
        own = [table.labels[i] for i in table.images_of_poses(poses)]
        best = max(own, key=lambda labels: int(np.isin(landmark, labels).sum())) \
            if own else np.zeros(0, np.int64)
        usable = usable.tolil()
        for c in landmark[~np.isin(landmark, best)]:
            usable[poses, int(c)] = False
        usable = usable.tocsr()
        usable.eliminate_zeros()
    poses = blind[0]
    raise VisibilityBuilderError(
        f'the update would leave a region (poses {poses[:6].tolist()}'
        f'{"..." if poses.size > 6 else ""}) without a model view: no image of the '
        'update or of the kept model views there shows its whole landmark; '
        're-explore that area too')


_REDRAWS = 3


def _regions_with_views(decomposition: Decomposition, database: LandmarkDatabase,
                        visibility: sp.csr_matrix, blocked: np.ndarray, needed: np.ndarray,
                        config: BuildConfig, table: ImageTable
                        ) -> tuple[list[RegionRecord], tuple[np.ndarray, np.ndarray] | None]:
    """Return the fewest regions with model views that serve ``needed``, or a blind one.

    ``(regions, None)``, or ``([], (poses, landmark))`` for a region without a model
    view that alone serves some needed poses.
    """
    world = replace_visibility(database, visibility, blocked)
    neighbourhoods = neighbourhood_matrix(world.adjacency, config.decomposition.rho)
    candidates, served, blind = [], [], []
    for region in decomposition.regions:
        poses = np.unique(region.poses).astype(np.int64)
        serves = np.intersect1d(np.flatnonzero(covered_poses(neighbourhoods, [poses])),
                                needed)
        if not serves.size:
            continue
        landmark = np.asarray(region.features, np.int64)
        extra = extra_features(visibility, poses, landmark, config.model_views)
        try:
            views = select_model_views(table, poses, landmark, extra, config.model_views)
        except VisibilityBuilderError:
            blind.append((poses, landmark, serves))
            continue
        candidates.append(RegionRecord(poses=poses, landmark=landmark, extra=extra,
                                       model_views=views))
        served.append(serves)
    reachable = np.unique(np.concatenate(served)) if served else np.zeros(0, np.int64)
    for poses, landmark, serves in blind:
        if not np.isin(serves, reachable).all():
            return [], (poses, landmark)
    if not candidates:
        return [], None
    chosen, _ = solve_set_cover(world.n_poses, reachable, served)
    return [candidates[int(index)] for index in chosen], None
