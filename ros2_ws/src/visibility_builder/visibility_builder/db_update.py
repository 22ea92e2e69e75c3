"""Update a landmark database from a partial re-exploration of a changed area.

The world changes after the exploration: a cupboard stands in front of a wall, a poster
is taken down or hung elsewhere. The regions whose landmark (thesis Sections 3.1, 5.1:
k features visible from every pose of the region) the world no longer shows serve
worse than they were built to (the localizer reports them stale,
:mod:`landmark_localizer.health`). Rebuilding the whole database needs the whole
building explored again; this step takes a bag of the changed area only, with poses
in the database's ``map`` frame, and rebuilds only what the change touched:

1. each image of the update bag is given the database's sampled pose it was taken at
   (its position within half the pose spacing, and with heading sectors its
   sector); images elsewhere are counted and left out;
2. its SIFT features are matched to the database's classes (ratio test against the
   nearest descriptor of another class), and a match is kept only where the class's
   triangulated scene point projects within ``max_reprojection_px`` of the feature from
   the image's pose (a poster hung elsewhere matches by appearance, not by place); a
   class without a scene point is kept where the old visibility had it at that pose or
   a neighbour;
3. the visibility of every updated pose becomes what its images show now (their SIFT
   run on images brightened to the localizer's exposure target); a pose the update
   went around on all sides but has no image of is taken as blocked (furniture stands
   there now): it sees nothing and leaves the pose graph (:func:`enclosed_poses`,
   :func:`replace_visibility`);
4. a region is *affected* when its landmark is no longer visible from each of its
   poses but the blocked ones in the new visibility; the other regions are kept as
   they are (landmark, extra features, model views), less their blocked poses;
5. the new visibility is decomposed as the database was built (its algorithm, k, rho,
   sigma), and a minimum set cover of those regions serves the k-coverable poses the
   kept regions leave unserved (HiGHS, :func:`~landmark_db.decomposition.set_cover.
   solve_set_cover`);
6. the new regions' model views come from the update's images and the kept model views
   at poses the update did not touch (Section 7.2's selection).

Features the exploration never saw (a poster hung on a bare wall) become new classes
(:mod:`visibility_builder.update_classes`), appended to the old ones. Classes no pose
sees any more keep their ids but lose their scene points, and kept regions lose the
extra features their poses no longer see. The scene points of no class (the
localizer's points between regions and for its refinement) that an update image shows
from near where they were seen give way to the update's own points: what the update
saw there is the world now (:func:`~visibility_builder.update_classes.looked_at`).

Writing is atomic: the database file is replaced only once the new one is complete, so
a failed update leaves the old one valid, and a localizer that opened it keeps what it
loaded.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
import math
import os
from typing import Any

import cv2
import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from landmark_db.database import FeatureClasses, LandmarkDatabase, RegionRecord
from landmark_db.database.build_info import utc_now_iso
from landmark_db.database.codebook import DescriptorCodebook
from landmark_db.database.compact import compact_database
from landmark_db.decomposition import service
from landmark_db.errors import LandmarkDbError
from vbn_common.errors import VbnCommonError
from vbn_common.exploration import Exploration, read_exploration
from vbn_common.features import ImageFeatures, SiftConfig, extract_many
from vbn_common.geometry.frames import world_points_to_camera
from vbn_common.workers import available_cores
from visibility_builder.build import BuildConfig, config_from_flat
from visibility_builder.build_config import TOP_SETTINGS
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.update_classes import (
    looked_at,
    merge_classes,
    merge_points,
    new_classes,
    select_points,
)
from visibility_builder.update_regions import image_table, new_regions, replace_visibility

__all__ = ['UpdateConfig', 'UpdateResult', 'assign_images', 'build_config_of',
           'label_features', 'update_database']


@dataclass(frozen=True)
class UpdateConfig:
    """How the update bag's features are given the database's classes.

    Attributes:
        ratio: Lowe's ratio between the nearest descriptor and the nearest of another
            class.
        max_reprojection_px: A match is kept where the class's scene point projects
            within this many pixels of the feature.
        max_descriptor_distance: A class looked for where its point projects is found
            when a feature there is this close (SIFT's L2 distance, 0 to 512: the same
            place re-imaged is below 200 in 97 % of cases, another texture above 400).
        pose_tolerance: An image belongs to a sampled pose within this fraction of the
            pose spacing.
        exposure_target: Brighten an update image whose 99th percentile is below this
            before SIFT, as the localizer does (a dimmer day would show fewer features).
        enclosed_m: A pose the update has no image of, with updated poses within this
            distance on all four sides, is taken as blocked now (furniture stands there):
            it sees nothing.
        min_seen_again: Least share of the (pose, class) pairs the database had at the
            updated poses that the update's images show again; below it the bag is
            refused as another place's (a hall's exploration against the room's
            database: 3.0 %; the changed worlds of the benchmark: 24 to 53 %).
        workers: Processes for SIFT (None: every core).
    """

    ratio: float = 0.8
    max_reprojection_px: float = 6.0
    max_descriptor_distance: float = 250.0
    pose_tolerance: float = 0.5
    exposure_target: float = 200.0
    enclosed_m: float = 1.0
    min_seen_again: float = 0.1
    workers: int | None = None

    def __post_init__(self) -> None:
        if not 0 < self.ratio <= 1 or self.max_reprojection_px <= 0 \
                or not 0 < self.pose_tolerance <= 1 or not 0 <= self.min_seen_again < 1:
            raise VisibilityBuilderError(f'invalid update settings: {self}')


@dataclass(frozen=True)
class UpdateResult:
    """The updated database and what the update did.

    Attributes:
        database: The updated database.
        counts: Images used and left out, poses updated, classes lost and kept at them,
            regions kept, affected and added, service before and after.
        affected: Indices (in the old database) of the regions rebuilt.
    """

    database: LandmarkDatabase
    counts: dict[str, Any]
    affected: np.ndarray


def build_config_of(database: LandmarkDatabase) -> BuildConfig:
    """Return the build settings the database was built with (as far as it stores them)."""
    info = database.info
    flat = {k: v for k, v in info.parameters.items()
            if '.' in k or k in TOP_SETTINGS}
    config = config_from_flat(flat)
    sift = SiftConfig(**{k: v for k, v in info.sift.items()
                         if k in {f.name for f in fields(SiftConfig)}})
    return replace(config, sift=sift, decomposition=replace(
        config.decomposition, algorithm=info.algorithm, k=info.k, rho=info.rho,
        sigma=info.sigma))


def assign_images(database: LandmarkDatabase, base_xy: np.ndarray, camera_yaw: np.ndarray,
                  tolerance: float = 0.5) -> np.ndarray:
    """Return ``(n,)`` the database pose each image was taken at, -1 for none.

    Args:
        database: The database (its sampled poses, spacing and heading sectors).
        base_xy: ``(n, 2)`` the images' ``base_link`` positions in ``map``.
        camera_yaw: ``(n,)`` the cameras' headings (used with heading sectors).
        tolerance: Within this fraction of the pose spacing.
    """
    poses = database.poses
    spacing = poses.spacing or _median_spacing(poses.xy)
    headings = int(database.info.parameters.get('pose_headings', 1) or 1)
    tree = cKDTree(poses.xy)
    out = np.full(len(base_xy), -1, np.int64)
    for i, near in enumerate(tree.query_ball_point(np.asarray(base_xy, float),
                                                   tolerance * spacing)):
        if not near:
            continue
        near = np.asarray(near, np.int64)
        if headings > 1:
            turn = np.abs(np.angle(np.exp(1j * (poses.yaw[near] - camera_yaw[i]))))
            near = near[turn <= math.pi / headings + 1e-9]
            if near.size == 0:
                continue
        out[i] = near[int(np.argmin(np.linalg.norm(poses.xy[near] - base_xy[i], axis=1)))]
    return out


def enclosed_poses(xy: np.ndarray, updated: np.ndarray, reach: float) -> np.ndarray:
    """Return the poses not in ``updated`` with an updated pose within ``reach`` on every side.

    Sides are the four 90 degree sectors around the pose (along and across ``map``'s
    axes): a pose the re-exploration went around on all sides but never took an image
    at is one the robot could not reach.

    Example:
        >>> xy = np.array([[0, 0], [1, 0], [-1, 0], [0, 1], [0, -1], [5, 5]], float)
        >>> enclosed_poses(xy, np.array([1, 2, 3, 4]), 1.0).tolist()
        [0]
    """
    updated = np.asarray(updated, np.int64)
    rest = np.setdiff1d(np.arange(len(xy)), updated)
    if rest.size == 0 or updated.size == 0:
        return np.zeros(0, np.int64)
    tree = cKDTree(xy[updated])
    out = []
    for pose, near in zip(rest, tree.query_ball_point(xy[rest], reach), strict=True):
        if len(near) < 4:
            continue
        d = xy[updated[near]] - xy[pose]
        side = np.floor(np.mod(np.arctan2(d[:, 1], d[:, 0]) + np.pi / 4, 2 * np.pi)
                        / (np.pi / 2)).astype(int)
        if np.unique(side).size == 4:
            out.append(pose)
    return np.asarray(out, np.int64)


def _median_spacing(xy: np.ndarray) -> float:
    if len(xy) < 2:
        return 0.25
    distances, _ = cKDTree(xy).query(xy, k=2)
    return float(np.median(distances[:, 1])) or 0.25


def label_features(features: ImageFeatures, camera_pose: np.ndarray, camera: Any,
                   config: UpdateConfig, classes: FeatureClasses,
                   matcher: cv2.DescriptorMatcher, class_points: np.ndarray,
                   near_visible: np.ndarray,
                   codebook: DescriptorCodebook | None = None) -> np.ndarray:
    """Return ``(n,)`` the database class of each feature of one update image (-1: none).

    Two ways to a class, as the module docstring says: *guided*, a class the old
    visibility had at the pose or a neighbour is looked for where its scene point
    projects (the nearest descriptor within ``max_reprojection_px``, kept when closer
    than ``max_descriptor_distance``); *matched*, a feature whose nearest descriptor's
    class passes the ratio test, kept where that class's point projects near it (or,
    for a class without a point, where the old visibility had it nearby).

    Args:
        features: The image's SIFT features.
        camera_pose: ``(x, y, yaw)`` of its camera in ``map``.
        camera: The camera model (pixels of points in the optical frame).
        config: Ratio, reprojection and descriptor limits.
        classes: The database's classes (descriptors and their offsets).
        matcher: A matcher trained on ``classes.descriptors`` (float32).
        class_points: ``(n_classes, 3)`` each class's scene point (NaN: none; ``z``
            from the camera height).
        near_visible: ``(n_classes,)`` bool, classes the old visibility had at the
            image's pose or a neighbour.
        codebook: the database's descriptor codebook, when its descriptors are codes:
            distances to them are judged as the original descriptors' would be
            (:meth:`~landmark_db.database.codebook.DescriptorCodebook.true_distances`).
    """
    true = codebook.true_distances if codebook is not None else np.asarray
    n = len(features)
    labels = np.full(n, -1, np.int64)
    if n == 0:
        return labels
    # Where each class's point falls in this image (NaN and False: no point, or outside).
    has_point = np.all(np.isfinite(class_points), axis=1)
    uv = np.full((len(class_points), 2), np.nan)
    shown = np.zeros(len(class_points), bool)
    if has_point.any():
        uv[has_point], shown[has_point] = camera.project(
            world_points_to_camera(camera_pose, 0.0, class_points[has_point]))
    descriptors = np.asarray(features.descriptors, np.float32)
    pairs: list[tuple[float, int, int]] = []   # (distance, feature, class)
    # Guided: expected classes where their points fall.
    expected = np.flatnonzero(near_visible & shown)
    if expected.size:
        tree = cKDTree(features.keypoints)
        for c, near in zip(expected, tree.query_ball_point(uv[expected],
                                                           config.max_reprojection_px),
                           strict=True):
            if not near:
                continue
            own = classes.descriptors[classes.offsets[c]:classes.offsets[c + 1]]
            distance = true(np.linalg.norm(descriptors[near][:, None]
                                           - own[None].astype(np.float32), axis=2).min(axis=1))
            best = int(np.argmin(distance))
            if distance[best] <= config.max_descriptor_distance:
                pairs.append((float(distance[best]), int(near[best]), int(c)))
    # Matched: the ratio test against the nearest descriptor of another class.
    owner = classes.descriptor_classes
    k = min(8, len(owner))
    matches = [m for m in matcher.knnMatch(descriptors, k=k) if m]
    if matches:
        rows = np.array([m[0].queryIdx for m in matches])
        index = np.array([[x.trainIdx for x in m] + [m[0].trainIdx] * (k - len(m))
                          for m in matches])
        distance = true(np.array([[x.distance for x in m] + [np.inf] * (k - len(m))
                                  for m in matches]))
        cls = owner[index]
        first = cls[:, 0]
        other = np.where(cls != first[:, None], distance, np.inf).min(axis=1)
        where = np.linalg.norm(uv[first] - features.keypoints[rows], axis=1)
        ok = (distance[:, 0] < config.ratio * other) & np.where(
            has_point[first], shown[first] & (where <= config.max_reprojection_px),
            near_visible[first])
        pairs += zip(distance[ok, 0].tolist(), rows[ok].tolist(), first[ok].tolist(),
                     strict=True)
    # One feature per class and one class per feature (eq. 6.3), closest first.
    taken_class: set[int] = set()
    for _, i, c in sorted(pairs):
        if labels[i] < 0 and c not in taken_class:
            labels[i] = c
            taken_class.add(c)
    return labels


def update_database(database: LandmarkDatabase, bag: str | os.PathLike[str],
                    config: UpdateConfig = UpdateConfig(),
                    on_stage: Callable[[str], None] | None = None) -> UpdateResult:
    """Update ``database`` from the re-exploration ``bag`` (see the module docstring).

    Raises:
        VisibilityBuilderError: The bag cannot be read, has no pose in ``map``, another
            camera, no image at any of the database's poses, images that show almost
            nothing the database saw there (``min_seen_again``: another place); or a
            region the update needs would have no model view. The message names the
            problem.
    """
    say = on_stage or (lambda _: None)
    build_config = build_config_of(database)
    say(f'read {bag}')
    try:
        exploration = read_exploration(bag, build_config.read)
    except VbnCommonError as error:
        raise VisibilityBuilderError(f'update bag {bag}: {error}') from error
    _check_camera(database, exploration, bag)
    frames = exploration.frames
    base = np.array([f.base_pose for f in frames], float)
    cameras = np.array([f.camera_pose for f in frames], float)
    pose_of = assign_images(database, base[:, :2], cameras[:, 2], config.pose_tolerance)
    used = np.flatnonzero(pose_of >= 0)
    if used.size == 0:
        raise VisibilityBuilderError(
            f'update bag {bag}: none of its {len(frames)} images was taken at a pose of the '
            f'database (within {config.pose_tolerance:g} of the pose spacing): is it a '
            'run through the place the database was built from, with poses in its map?')

    say(f'features of {used.size} images')
    results = extract_many([frames[i].image for i in used], build_config.sift, config.workers,
                           exposure=config.exposure_target)
    features: dict[int, ImageFeatures] = {}
    for i, result in zip(used, results, strict=True):
        if not isinstance(result, str):
            features[int(i)] = result
    if not features:
        raise VisibilityBuilderError(f'update bag {bag}: no image of it could be decoded')

    say('classes')
    classes = database.classes
    n_classes = classes.n_classes
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    matcher.add([np.asarray(classes.descriptors, np.float32)])
    matcher.train()
    class_points = database.points.class_points(n_classes)
    old = classes.visibility.tocsr()
    graph = database.to_world_instance().adjacency
    near = (graph + sp.identity(graph.shape[0], format='csr')).astype(bool) @ old
    labels: dict[int, np.ndarray] = {}
    camera = exploration.camera_model()
    for i, feats in features.items():
        labels[i] = label_features(
            feats, cameras[i], camera, config, classes, matcher, class_points,
            np.asarray(near[int(pose_of[i])].todense()).ravel(), database.codebook)
    updated = np.unique(pose_of[list(features)])
    blocked = enclosed_poses(database.poses.xy, updated, config.enclosed_m)
    # What the updated poses see now; the blocked ones see nothing; the rest as before.
    images = sorted(features)
    seen = [labels[i][labels[i] >= 0] for i in images]
    now = sp.csr_matrix((np.ones(sum(c.size for c in seen), bool), (
        np.repeat(pose_of[images], [c.size for c in seen]), np.concatenate(seen))),
        shape=old.shape)
    changed = np.zeros(old.shape[0], bool)
    changed[updated] = changed[blocked] = True
    unchanged = sp.diags((~changed).astype(np.int8), dtype=np.int8)
    visibility = (unchanged @ old + now).astype(bool).tocsr()
    kept_classes = old[changed].multiply(visibility[changed]).nnz
    lost = old[changed].nnz - kept_classes
    if kept_classes < config.min_seen_again * (kept_classes + lost):
        raise VisibilityBuilderError(
            f'update bag {bag}: its images show {kept_classes} of the {kept_classes + lost} '
            f'(pose, feature) pairs the database had at the {updated.size} poses they were '
            f'taken at ({100 * kept_classes / max(kept_classes + lost, 1):.1f} %, at least '
            f'{100 * config.min_seen_again:g} % expected): a bag of another place, or poses '
            'in another map frame?')

    say('new classes')
    fresh = new_classes(database, updated, images, [features[i] for i in images],
                        [labels[i] for i in images], pose_of, cameras, frames, camera,
                        build_config, config.workers or available_cores())
    n_old = classes.n_classes
    for m, i in enumerate(images):
        labels[i] = np.where(labels[i] >= 0, labels[i],
                             np.where(fresh.labels[m] >= 0, fresh.labels[m] + n_old, -1))
    merged = merge_classes(classes, visibility, fresh, updated)
    visibility = merged.visibility
    # The scene points of no class that the update's images show from near where they
    # were seen give way to the update's own (a rehung poster's old points would pull a
    # pose towards where it hung: room seed 1, p95 1.28 -> 0.24 cm).
    # (Only when the update triangulated points of its own: a single updated pose has
    # none, and its images alone tell nothing about the old ones.)
    old_points = database.points
    stale = (old_points.class_ids < 0) & looked_at(old_points, cameras[images], camera) \
        & (fresh.points.n_points > 0)
    points = merge_points(select_points(old_points, ~stale), fresh.points, n_old)
    # A class no pose sees any more (its poster is gone) keeps its id but loses its point:
    # the localizer would otherwise look for it, or take its texture hung elsewhere.
    seen_anywhere = np.asarray(visibility.sum(axis=0)).ravel() > 0
    points = select_points(points, (points.class_ids < 0) | seen_anywhere[
        np.maximum(points.class_ids, 0)])

    say('regions')
    world = replace_visibility(database, visibility, blocked)
    poses = replace(database.poses, edges=world.edges)   # blocked poses' edges gone
    info = database.info
    # A region keeps its poses but the blocked ones; it stays when its landmark is
    # visible from each of them.
    reachable = [r.poses[~np.isin(r.poses, blocked)] for r in database.regions]
    valid = [poses.size > 0 and bool(np.all(visibility[poses][:, r.landmark].toarray()))
             for r, poses in zip(database.regions, reachable, strict=True)]
    kept = [_trimmed(replace(r, poses=poses), visibility, build_config)
            for r, poses, ok in zip(database.regions, reachable, valid, strict=True) if ok]
    affected = np.flatnonzero(~np.asarray(valid, bool))
    needed = service(world, [r.poses for r in kept], info.k, info.rho).unserved
    added: list[RegionRecord] = []
    if needed.size:
        added = new_regions(database, visibility, blocked, needed, build_config,
                             image_table(database, updated, features, labels, pose_of,
                                          cameras, frames))
    regions = tuple(kept) + tuple(added)
    after = service(world, [r.poses for r in regions], info.k, info.rho)
    before = database.service()
    updated_info = replace(info, created_utc=utc_now_iso(), parameters={
        **info.parameters, 'updates': [*info.parameters.get('updates', []), {
            'bag': str(bag), 'utc': utc_now_iso(), 'poses': int(updated.size),
            'regions_rebuilt': int(affected.size), 'regions_added': len(added)}]})
    try:
        new = LandmarkDatabase(info=updated_info, poses=poses,
                               classes=merged, regions=regions,
                               uncovered=after.unserved, points=points)
        # The kept regions keep their codes: the new descriptors take the same codebook.
        new, _ = compact_database(
            new, database.codebook.code_size if database.codebook is not None
            else build_config.descriptor_bytes, build_config.points.patch_quality,
            np.random.default_rng(build_config.decomposition.seed), database.codebook)
    except LandmarkDbError as error:
        raise VisibilityBuilderError(f'the updated database is not consistent: {error}'
                                     ) from error
    counts = {'images': len(frames), 'images_used': len(features),
              'images_elsewhere': int(len(frames) - used.size),
              'undecodable': int(used.size - len(features)),
              'poses_updated': int(updated.size), 'poses_blocked': int(blocked.size),
              'classes_kept_at_updated_poses': kept_classes,
              'classes_lost_at_updated_poses': lost, 'classes_new': fresh.n_classes,
              'regions_before': database.n_regions, 'regions_kept': len(kept),
              'regions_affected': int(affected.size), 'regions_added': len(added),
              'regions_after': len(regions),
              'served_before': f'{before.served} of {before.k_coverable}',
              'served_after': f'{after.served} of {after.k_coverable}'}
    return UpdateResult(new, counts, affected)


def _trimmed(region: RegionRecord, visibility: sp.csr_matrix, config: BuildConfig
             ) -> RegionRecord:
    """Return a kept region with its extra features cut to those its poses still see."""
    share = np.asarray(visibility[region.poses][:, region.extra].sum(axis=0)).ravel() \
        / max(region.poses.size, 1)
    extra = region.extra[share >= config.model_views.extra_min_fraction - 1e-9]
    if extra.size == region.extra.size:
        return region
    classes = np.concatenate([region.landmark, extra])
    views = tuple(replace(view, class_ids=np.where(np.isin(view.class_ids, classes),
                                                   view.class_ids, -1))
                  for view in region.model_views)
    return RegionRecord(poses=region.poses, landmark=region.landmark, extra=extra,
                        model_views=views)


def _check_camera(database: LandmarkDatabase, exploration: Exploration, bag: Any) -> None:
    info, camera = exploration.camera_info, database.info.camera
    same = (info.width, info.height) == (camera.width, camera.height) and np.allclose(
        np.asarray(info.k, float).reshape(3, 3), camera.K, rtol=1e-6, atol=1e-9) and \
        np.allclose(np.asarray(info.d, float).ravel()[:camera.D.size], camera.D, atol=1e-9) \
        and len(np.ravel(info.d)) == camera.D.size
    if not same:
        raise VisibilityBuilderError(
            f'update bag {bag}: its camera ({info.width} x {info.height}, fx '
            f"{float(np.ravel(info.k)[0]):g}) is not the database's ({camera.width} x "
            f'{camera.height}, fx {float(camera.K[0, 0]):g}): a bag of another robot?')
