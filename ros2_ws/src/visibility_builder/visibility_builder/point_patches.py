"""The exploration's image around each scene point, kept to measure the point by.

Not in the thesis. The localizer measures scene points in its tracked frames
(:mod:`landmark_localizer.scene_tracks`). Searching each one by SIFT in the frame spends
the frame's few SIFT windows, and a keypoint found in the frame is only where SIFT put
it there. A patch cut from one exploration image, centred on the point's reprojection
in that image, lets the localizer warp the patch to where the frame's pose puts the
point and align it there (one Lucas-Kanade call for every point): no SIFT, and every
measurement is of the same 3-D point the refinement poses the frame on.

For each point:

1. its **patch view**: among the exploration images that saw it, the one whose camera is
   nearest the centre of the images that saw it (:attr:`ScenePoints.seen_from`), so the
   viewpoint changes least over the places the localizer searches it from; an image
   tilted beyond the mount (a shaking robot) or one where the patch would leave the
   image is not a patch view;
2. the ``s x s`` patch, bilinearly sampled around the point's reprojection in that view
   (``cv2.getRectSubPix``), so its centre pixel *is* the point;
3. its **axes**: the 3-D offsets from the point, on the surface's plane through it
   where the neighbouring points fix one (:mod:`.surface_normals`), else on the plane
   facing the patch view's camera, whose projections move one patch pixel right and one
   down. With them a frame's pose predicts the patch's affine warp in that frame.

A point with no patch view keeps no patch. Cost: one decode per patch view image and a
few vectorised passes (about 0.3 s on the room's 200 panoramas).
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import cv2
import numpy as np

from vbn_common.geometry.camera import CameraModel
from vbn_common.geometry.rays import intersect_rays
from vbn_common.images import ImageDecodeError, decode_image
from vbn_common.patch_alignment import align_patches, patch_maps
from visibility_builder.verification import map_rays

__all__ = ['MIN_FACING_COS', 'choose_patch_views', 'patch_axes', 'patch_sources',
           'point_patches', 'triangulate_on_patches']

#: A surface normal is used for a patch's axes only where the patch view sees the surface
#: within about 72 degrees of face on (its cosine): nearer grazing, a few millimetres of
#: the fitted plane's error stretch the axes by a pixel.
MIN_FACING_COS = 0.3


def patch_sources(frames: Sequence[Any]) -> tuple[Callable[[int], np.ndarray | None],
                                                   np.ndarray]:
    """Return what :func:`point_patches` cuts from: the exploration's images.

    Args:
        frames: The exploration's frames (``image``, and ``camera_tilt`` where the pose
            source tilts a frame beyond the mount).

    Returns:
        ``(decode, usable)``: image i's grey pixels (None when it cannot be decoded: the
        features step skipped it with a warning), and ``(n,)`` bool, the frames not
        tilted beyond the mount (a patch of a tilted frame is turned).
    """
    def decode(i: int) -> np.ndarray | None:
        try:
            return decode_image(frames[i].image)
        except ImageDecodeError:
            return None
    usable = np.array([getattr(f, 'camera_tilt', None) is None for f in frames], bool)
    return decode, usable


def _local(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Levelled optical coordinates (x right, y down, z forward) of map points.

    ``points`` z is the height above the camera, as the scene points keep it.
    """
    dx, dy = points[:, 0] - pose[:, 0], points[:, 1] - pose[:, 1]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    forward, left = c * dx + s * dy, -s * dx + c * dy
    return np.column_stack([-left, -points[:, 2], forward])


def choose_patch_views(points: np.ndarray, member_point: np.ndarray,
                       member_image: np.ndarray, camera_poses: np.ndarray,
                       centres: np.ndarray, camera: CameraModel, size: int,
                       usable_image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pick each point's patch view (step 1) and the point's pixel there.

    Args:
        points: ``(n, 3)`` the points.
        member_point: ``(m,)`` the point each member (an image that saw a point) belongs to.
        member_image: ``(m,)`` the member's image.
        camera_poses: ``(n_images, 3)`` camera ``(x, y, heading)``.
        centres: ``(n, 2)`` where each point was seen from (its images' centre).
        camera: the camera as mounted.
        size: the patch side (odd), pixels.
        usable_image: ``(n_images,)`` bool, the images a patch may come from.

    Returns:
        ``(image (n,), uv (n, 2))``: each point's patch view (-1: none) and its pixel there.
    """
    n = len(points)
    image = np.full(n, -1, np.int64)
    uv = np.full((n, 2), np.nan)
    if not len(member_point):
        return image, uv
    pose = np.asarray(camera_poses, float)[member_image]
    proj, valid = camera.project(_local(points[member_point], pose))
    half = size // 2 + 1          # room for the bilinear sample's neighbours
    inside = valid & np.all(np.isfinite(proj), axis=1) & \
        (proj[:, 0] >= half) & (proj[:, 0] <= camera.width - 1 - half) & \
        (proj[:, 1] >= half) & (proj[:, 1] <= camera.height - 1 - half) & \
        np.asarray(usable_image, bool)[member_image]
    rows = np.flatnonzero(inside)
    if not len(rows):
        return image, uv
    distance = np.linalg.norm(pose[rows, :2] - centres[member_point[rows]], axis=1)
    order = rows[np.lexsort((distance, member_point[rows]))]
    first = order[np.concatenate([[True], member_point[order][1:] != member_point[order][:-1]])]
    image[member_point[first]] = member_image[first]
    uv[member_point[first]] = proj[first]
    return image, uv


def patch_axes(points: np.ndarray, camera_poses: np.ndarray, uv: np.ndarray,
               camera: CameraModel, normals: np.ndarray | None = None) -> np.ndarray:
    """Step 3: the 3-D offsets that move each point's projection one pixel right and down.

    Args:
        points: ``(n, 3)`` the points (z above the camera).
        camera_poses: ``(n, 3)`` the camera ``(x, y, heading)`` each point is seen from.
        uv: ``(n, 2)`` the point's pixel in that camera.
        camera: the camera as mounted.
        normals: ``(n, 3)`` the surface's normal at each point
            (:func:`.surface_normals.surface_normals`; NaN: unknown), or None. The axes
            lie on that plane where it is known and faces the camera at least
            :data:`MIN_FACING_COS`, else on the plane facing the camera.

    Returns:
        ``(n, 2, 3)`` float32: row 0 the offset for one pixel right, row 1 one pixel down;
        NaN where a shifted pixel's ray misses the plane.
    """
    n = len(points)
    points = np.asarray(points, float)
    pose = np.asarray(camera_poses, float)
    centre = np.column_stack([pose[:, :2], np.zeros(n)])
    plane = points - centre
    plane /= np.maximum(np.linalg.norm(plane, axis=1), 1e-12)[:, None]
    if normals is not None:
        normals = np.asarray(normals, float).reshape(n, 3)
        facing = np.einsum('ij,ij->i', np.nan_to_num(normals), plane)
        use = np.all(np.isfinite(normals), axis=1) & (np.abs(facing) >= MIN_FACING_COS)
        plane[use] = normals[use] * np.sign(facing[use])[:, None]
    reach = np.einsum('ij,ij->i', points - centre, plane)
    out = np.full((n, 2, 3), np.nan, np.float32)
    for axis in range(2):
        shifted = np.asarray(uv, float).copy()
        shifted[:, axis] += 1.0
        rays = map_rays(camera.unproject(shifted), pose[:, 2])
        along = np.einsum('ij,ij->i', rays, plane)
        ok = along > 1e-6
        t = np.where(ok, reach / np.where(ok, along, 1.0), np.nan)
        out[:, axis] = (centre + t[:, None] * rays - points).astype(np.float32)
    return out


def point_patches(points: np.ndarray, view_image: np.ndarray, uv: np.ndarray,
                  camera_poses: np.ndarray, camera: CameraModel, size: int,
                  decode: Callable[[int], np.ndarray | None],
                  normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cut each point's patch in its patch view, and its axes (steps 2 and 3).

    Args:
        points: ``(n, 3)`` the points.
        view_image: ``(n,)`` each point's patch view (-1: none), from
            :func:`choose_patch_views`.
        uv: ``(n, 2)`` the point's pixel there.
        camera_poses: ``(n_images, 3)`` camera ``(x, y, heading)``.
        camera: the camera as mounted.
        size: the patch side (odd), pixels.
        decode: the grey image of an image index (None when it cannot be decoded).
        normals: ``(n, 3)`` each point's surface normal (NaN: unknown) for its axes
            (:func:`patch_axes`), or None: every patch on the plane facing its view.

    Returns:
        ``(patches (n, size, size) uint8, axes (n, 2, 3) float32)``: zero patches and NaN
        axes for the points with no patch.
    """
    n = len(points)
    patches = np.zeros((n, size, size), np.uint8)
    axes = np.full((n, 2, 3), np.nan, np.float32)
    with_view = np.flatnonzero(np.asarray(view_image) >= 0)
    if not len(with_view):
        return patches, axes
    pose = np.asarray(camera_poses, float)
    axes[with_view] = patch_axes(points[with_view], pose[view_image[with_view]],
                                 uv[with_view], camera,
                                 None if normals is None else normals[with_view])
    cut = np.zeros(n, bool)
    for image in np.unique(view_image[with_view]):
        gray = decode(int(image))
        if gray is None:
            continue
        gray = np.ascontiguousarray(gray, np.float32)
        for i in with_view[view_image[with_view] == image]:
            patches[i] = np.clip(np.rint(cv2.getRectSubPix(
                gray, (size, size), (float(uv[i, 0]), float(uv[i, 1])))), 0, 255)
            cut[i] = True
    ok = cut & np.all(np.isfinite(axes.reshape(n, 6)), axis=1)
    patches[~ok] = 0
    axes[~ok] = np.nan
    return patches, axes


def triangulate_on_patches(points: np.ndarray, patches: np.ndarray, axes: np.ndarray,
                           member_point: np.ndarray, member_image: np.ndarray,
                           camera_poses: np.ndarray, camera: CameraModel,
                           decode: Callable[[int], np.ndarray | None], min_views: int,
                           max_shift_px: float = 3.0) -> tuple[np.ndarray, np.ndarray]:
    """Triangulate each point where its patch is seen in the images that saw it.

    A SIFT keypoint lies where SIFT puts it at that image's scale: the same feature seen
    from elsewhere is found a few tenths of a pixel off, and the least-squares point of
    those rays is not the patch's centre seen from elsewhere. Aligning the point's own
    patch in every image that saw it (:func:`vbn_common.patch_alignment.align_patches`,
    from the pixel and warp the current point predicts) measures the patch's centre
    itself; the rays through those pixels give the point again. This is what the
    localizer measures, so its measurements and the points agree.

    Args:
        points: ``(n, 3)`` the points (z above the camera).
        patches: ``(n, s, s)`` their patches.
        axes: ``(n, 2, 3)`` the patches' axes (NaN: the point has no patch).
        member_point: ``(m,)`` the point of each image that saw a point.
        member_image: ``(m,)`` that image.
        camera_poses: ``(n_images, 3)`` camera ``(x, y, heading)``.
        camera: the camera as mounted.
        decode: the grey image of an image index (None if it cannot be decoded).
        min_views: least images the patch must be found in for the point to move.
        max_shift_px: farthest a found centre may lie from the current point's pixel.

    Returns:
        ``(points (n, 3), found (n,))``: the points, moved where their patch was found in
        at least ``min_views`` images, and in how many images it was found.
    """
    n = len(points)
    has = np.all(np.isfinite(axes.reshape(n, 6)), axis=1)
    rows = np.flatnonzero(has[member_point])
    point, image = member_point[rows], member_image[rows]
    pose = np.asarray(camera_poses, float)[image]
    m = len(rows)
    ends = np.concatenate([points[point], points[point] + axes[point, 0],
                           points[point] + axes[point, 1]])
    proj, valid = camera.project(_local(ends, np.tile(pose, (3, 1))))
    proj, valid = proj.reshape(3, m, 2), valid.reshape(3, m).all(axis=0)
    maps = patch_maps(proj, camera.width if camera.kind == 'panoramic' else None)
    pixel = np.full((m, 2), np.nan)
    order = np.argsort(image, kind='stable')
    starts = np.flatnonzero(np.r_[True, image[order][1:] != image[order][:-1]])
    for first, last in zip(starts, np.r_[starts[1:], m], strict=True):
        these = order[first:last]
        these = these[valid[these]]
        gray = decode(int(image[order[first]])) if len(these) else None
        if gray is None:
            continue
        pixel[these], _ = align_patches(gray, patches[point[these]], proj[0, these],
                                        maps[these], max_shift_px)
    good = np.all(np.isfinite(pixel), axis=1)
    found = np.bincount(point[good], minlength=n)
    rays = map_rays(camera.unproject(pixel[good]), pose[good, 2])
    centres = np.column_stack([pose[good, :2], np.zeros(int(good.sum()))])
    moved = intersect_rays(rays, centres, point[good], n)
    out = np.array(points, float)
    move = (found >= min_views) & np.all(np.isfinite(moved), axis=1)
    out[move] = moved[move]
    return out, found
