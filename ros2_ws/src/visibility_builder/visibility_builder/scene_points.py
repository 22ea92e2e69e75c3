"""The scene points of the database: each verified class triangulated from all its images.

Not in the thesis; a departure with a reason. A camera that does not see all
around has places (facing a near wall) where no k features are visible from a whole
neighbourhood, so the decomposition leaves them without a region, and the localizer
had only the points it could triangulate from the regions' two or three model views.
The exploration saw those places from a few poses, and the geometric check of
:mod:`.verification` has already shown that each class's member rays meet in one
point. This step keeps those points, with one descriptor each, as
:class:`~landmark_db.database.points.ScenePoints`:

1. every member of a class gives a ray from its camera centre (``(x, y)`` of the image,
   at the camera height) through its keypoint, levelled by the mount;
2. the least-squares point of the rays (one 3 x 3 solve per class, batched);
3. a class gives a point when at least ``min_views`` images see it, its rays span at
   least ``min_angle_deg`` (parallel rays fix no depth), the point lies in front of
   every member at most ``max_distance_m`` away, and every member reprojects within
   ``max_error_px`` (the verification's tolerance is per keypoint size; this one keeps
   only points sharp enough to pose a camera by);
4. its descriptor is the member nearest the members' mean;
5. where it was seen from: the centre of its images' camera positions and the largest
   distance of one from it (the localizer searches a point only near there);
6. its patch in one exploration image, and the patch's axes (:mod:`.point_patches`) on
   the surface its neighbouring points fix (:mod:`.surface_normals`), when the images
   are given, ``patch_px`` is not 0 and at least ``patch_min_views`` images see it;
   such a point is triangulated again where its patch is found.

A class the filters kept carries its database id; the others -1. Cost: a sort and
linear passes over the classified features (about 0.1 s for the room's 60k members).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
import math

import numpy as np

from landmark_db.database.points import ScenePoints
from vbn_common.features import ImageFeatures
from vbn_common.geometry.camera import CameraModel
from vbn_common.geometry.rays import intersect_rays
from visibility_builder.errors import VisibilityBuilderError
from visibility_builder.point_patches import (
    choose_patch_views,
    point_patches,
    triangulate_on_patches,
)
from visibility_builder.surface_normals import surface_normals
from visibility_builder.verification import map_rays, reprojection_error

__all__ = ['PointsConfig', 'central_members', 'labels_by_image', 'scene_points']


@dataclass(frozen=True)
class PointsConfig:
    """Which verified classes become scene points.

    Attributes:
        enabled: keep scene points (False: the database holds none).
        min_views: least exploration images that see the point.
        min_angle_deg: least angle between two of its rays, degrees.
        max_distance_m: farthest the point lies from a camera that sees it, metres.
        max_error_px: largest reprojection error of a member, pixels.
        patch_px: side of the exploration patch kept with a point (odd; 0: none),
            pixels: the localizer aligns it where a frame's pose puts the point.
        patch_min_views: only a point seen by at least this many exploration images
            keeps a patch (the patches are most of a point's bytes). 5, not 8: the
            localizer then has more patched points to choose from where it stands
            (measured over three seeds of five runs: the pinhole room's p95
            0.58 -> 0.41 cm, the panoramic runs' 0.28 to 0.35 -> 0.25 to 0.31 cm).
        patch_quality: JPEG quality the file stores the patches at, 1 to 100 (0: whole
            pixels); at 70 a 15 px patch takes about 45 bytes instead of 225 (70, not
            80: with patches from 5 views the fisheye room's file stays within a third
            of the structure-based peer's compact map).
        patch_normal_radius_m: the patches' axes lie on the plane that the points within
            this distance (metres) fix (:mod:`.surface_normals`; 0: every patch on the
            plane facing its view). On a plane facing the view, a patch seen obliquely
            was aligned a few tenths of a pixel off in the localizer's frames.
    """

    enabled: bool = True
    min_views: int = 3
    min_angle_deg: float = 2.0
    max_distance_m: float = 30.0
    max_error_px: float = 1.5
    patch_px: int = 15
    patch_min_views: int = 5
    patch_quality: int = 70
    patch_normal_radius_m: float = 0.3

    def __post_init__(self) -> None:
        if isinstance(self.patch_quality, bool) or \
                int(self.patch_quality) != self.patch_quality or \
                not 0 <= self.patch_quality <= 100:
            raise VisibilityBuilderError(f'points.patch_quality must be an integer 0..100 '
                                         f'(0: whole), got {self.patch_quality!r}')
        if isinstance(self.patch_min_views, bool) or \
                int(self.patch_min_views) != self.patch_min_views or self.patch_min_views < 2:
            raise VisibilityBuilderError(f'points.patch_min_views must be an integer >= 2, '
                                         f'got {self.patch_min_views!r}')
        if isinstance(self.patch_px, bool) or int(self.patch_px) != self.patch_px or \
                self.patch_px < 0 or (self.patch_px and (self.patch_px < 7
                                                         or self.patch_px % 2 == 0)):
            raise VisibilityBuilderError(f'points.patch_px must be 0 or an odd integer '
                                         f'>= 7, got {self.patch_px!r}')
        if isinstance(self.min_views, bool) or int(self.min_views) != self.min_views or \
                self.min_views < 2:
            raise VisibilityBuilderError(f'points.min_views must be an integer >= 2, '
                                         f'got {self.min_views!r}')
        if not (isinstance(self.patch_normal_radius_m, (int, float))
                and not isinstance(self.patch_normal_radius_m, bool)
                and math.isfinite(self.patch_normal_radius_m)
                and self.patch_normal_radius_m >= 0):
            raise VisibilityBuilderError(f'points.patch_normal_radius_m must be a number '
                                         f'>= 0, got {self.patch_normal_radius_m!r}')
        for name in ('min_angle_deg', 'max_distance_m', 'max_error_px'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise VisibilityBuilderError(f'points.{name} must be a positive number, '
                                             f'got {value!r}')


def scene_points(image_labels: Sequence[np.ndarray], features: Sequence[ImageFeatures],
                 camera_poses: np.ndarray, camera: CameraModel, kept: np.ndarray,
                 config: PointsConfig = PointsConfig(),
                 decode: Callable[[int], np.ndarray | None] | None = None,
                 usable_image: np.ndarray | None = None) -> ScenePoints:
    """Triangulate the verified classes into scene points.

    Args:
        image_labels: per image, ``(n_i,)`` the verified class of each feature (-1: none),
            before the filters' renumbering.
        features: per image, its SIFT features (keypoints levelled to the mount).
        camera_poses: ``(n_images, 3)`` camera ``(x, y, heading)`` in ``map``.
        camera: the camera as mounted (its rays levelled).
        kept: ``(c,)`` the classes the filters kept: class ``kept[j]`` is database class j.
        config: the thresholds.
        decode: the grey image of an image index (None if it cannot be decoded); without
            it the points keep no patch.
        usable_image: ``(n_images,)`` bool, the images a patch may be cut from (default
            all); an image tilted beyond the mount is not one.

    Returns:
        The points, sorted by class.
    """
    if not config.enabled:
        return ScenePoints.empty()
    # Only the classified features, image by image: the exploration's every descriptor
    # at once is gigabytes on a large floor.
    rows = [np.flatnonzero(np.asarray(lab) >= 0) for lab in image_labels]
    if not sum(len(r) for r in rows):
        return ScenePoints.empty()
    labels = np.concatenate([np.asarray(lab, np.int64)[r]
                             for lab, r in zip(image_labels, rows, strict=True)])
    image = np.repeat(np.arange(len(rows)), [len(r) for r in rows])
    uv = np.concatenate([f.keypoints[r] for f, r in zip(features, rows, strict=True)]
                        ).astype(float)
    descriptors = np.concatenate([f.descriptors[r]
                                  for f, r in zip(features, rows, strict=True)])
    pose = np.asarray(camera_poses, float)[image]
    rays = map_rays(camera.unproject(uv), pose[:, 2])
    centres = np.column_stack([pose[:, :2], np.zeros(len(pose))])

    ids, inverse = np.unique(labels, return_inverse=True)
    n = len(ids)
    views = np.bincount(inverse, minlength=n)
    ok = views >= config.min_views
    points = intersect_rays(rays, centres, inverse, n, solve=ok)
    # Spread: the largest angle of a member's ray from the class's mean ray.
    mean = np.zeros((n, 3))
    np.add.at(mean, inverse, rays)
    mean /= np.maximum(np.linalg.norm(mean, axis=1, keepdims=True), 1e-12)
    off = np.arccos(np.clip(np.einsum('ij,ij->i', rays, mean[inverse]), -1, 1))
    spread = np.zeros(n)
    np.maximum.at(spread, inverse, off)
    ok &= 2 * spread >= math.radians(config.min_angle_deg)
    # In front, not too far, and sharp in every member.
    to_point = points[inverse] - centres
    depth = np.einsum('ij,ij->i', to_point, rays)
    distance = np.linalg.norm(to_point, axis=1)
    error = reprojection_error(points[inverse], pose, uv, camera)
    bad = ~np.isfinite(depth) | (depth <= 0) | (distance > config.max_distance_m) | \
        ~(error <= config.max_error_px)
    ok &= np.bincount(inverse, weights=bad, minlength=n) == 0

    chosen = central_members(descriptors, inverse, n)
    # Where it was seen from: the centre of its images' positions and their spread.
    centre = np.zeros((n, 2))
    np.add.at(centre, inverse, pose[:, :2])
    centre /= np.maximum(views, 1)[:, None]
    radius = np.zeros(n)
    np.maximum.at(radius, inverse, np.linalg.norm(pose[:, :2] - centre[inverse], axis=1))

    remap = np.full(int(max(ids.max(), kept.max(initial=-1))) + 1, -1, np.int64)
    remap[np.asarray(kept, np.int64)] = np.arange(len(kept))
    keep = np.flatnonzero(ok)
    patches = axes = None
    if decode is not None and config.patch_px and len(keep):
        row_of = np.full(n, -1, np.int64)
        row_of[keep] = np.arange(len(keep))
        member = np.flatnonzero((row_of[inverse] >= 0) &
                                (views[inverse] >= config.patch_min_views))
        usable = np.ones(len(camera_poses), bool) if usable_image is None else usable_image
        xyz = points[keep]
        for attempt in range(2):
            normals = surface_normals(xyz, config.patch_normal_radius_m) \
                if config.patch_normal_radius_m > 0 else None
            view, view_uv = choose_patch_views(
                xyz, row_of[inverse[member]], image[member], camera_poses, centre[keep],
                camera, config.patch_px, usable)
            patches, axes = point_patches(xyz, view, view_uv, camera_poses, camera,
                                          config.patch_px, decode, normals)
            if attempt == 0:   # each point where its patch is, then its patch there
                xyz, _ = triangulate_on_patches(
                    xyz, patches, axes, row_of[inverse[member]], image[member],
                    camera_poses, camera, decode, config.min_views)
        points[keep] = xyz
    return ScenePoints(points[keep], remap[ids[keep]], descriptors[chosen[keep]],
                       views[keep], np.column_stack([centre[keep], radius[keep]]),
                       patches, axes)


def central_members(descriptors: np.ndarray, group: np.ndarray, n: int,
                    chunk: int = 1 << 18) -> np.ndarray:
    """Return the member of each group nearest the group's mean descriptor.

    In chunks of ``chunk`` members, in float32: a whole floor's members in float64 were
    tens of gigabytes (a 19,344-image pinhole floor was killed for memory here).

    Args:
        descriptors: ``(m, d)`` the members' descriptors (any numeric type).
        group: ``(m,)`` each member's group, in ``[0, n)``.
        n: number of groups.
        chunk: members per chunk.

    Returns:
        ``(n,)`` the row of each group's central member, -1 for an empty group.

    Example:
        >>> central_members(np.array([[0], [4], [5], [9]]), np.array([0, 0, 0, 1]), 3).tolist()
        [1, 3, -1]
    """
    if not len(group):
        return np.full(n, -1, np.int64)
    order = np.argsort(group, kind='stable')
    sorted_group = group[order]
    total = np.zeros((n, descriptors.shape[1]), np.float64)
    for start in range(0, len(order), chunk):
        rows, g = order[start:start + chunk], sorted_group[start:start + chunk]
        first = np.flatnonzero(np.concatenate([[True], g[1:] != g[:-1]]))
        total[g[first]] += np.add.reduceat(descriptors[rows].astype(np.float32), first,
                                           axis=0)
    centre = (total / np.maximum(np.bincount(group, minlength=n), 1)[:, None]
              ).astype(np.float32)
    dist = np.empty(len(order), np.float32)
    for start in range(0, len(order), chunk):
        rows, g = order[start:start + chunk], sorted_group[start:start + chunk]
        dist[start:start + len(rows)] = np.linalg.norm(
            descriptors[rows].astype(np.float32) - centre[g], axis=1)
    best = np.lexsort((dist, sorted_group))   # sorted_group is sorted: ties by distance
    head = best[np.concatenate([[True], sorted_group[best][1:] != sorted_group[best][:-1]])]
    chosen = np.full(n, -1, np.int64)
    chosen[sorted_group[head]] = order[head]
    return chosen


def labels_by_image(frames_of_pose: Sequence[Sequence[int]], pose_labels: Sequence[np.ndarray],
                    n_features: Sequence[int]) -> list[np.ndarray]:
    """Split each pose's labels (its images' features concatenated) into its images'."""
    out: list[np.ndarray] = [np.zeros(0, np.int64)] * len(n_features)
    for members, labels in zip(frames_of_pose, pose_labels, strict=True):
        start = 0
        for i in members:
            out[i] = np.asarray(labels[start:start + n_features[i]], np.int64)
            start += n_features[i]
    return out
