"""Scene points measured by the exploration's own patches.

Not in the thesis. :mod:`.scene_tracks` measures scene points in the tracked frames from
a patch of the frame where SIFT found each point; births spend the frame's few SIFT
windows (on ``room_run`` about four a frame, so about 15 points were measured where 40
were asked for). A database of schema 4 keeps, with each scene point, a patch of one
exploration image centred on the point and the patch's axes
(:mod:`visibility_builder.point_patches`). :class:`PatchTracks` measures the points from
those patches instead, in every tracked frame, with no SIFT:

- **Choose**: the points measured in the previous frame, then points seen from near the
  current position (as :mod:`.scene_tracks`, but within ``scene_patch_margin_m`` of
  their images' spread rather than SIFT's 0.15 m), round the image's cells emptiest first,
  up to ``scene_tracks``, and not searched for ``redetect_cooldown`` frames after the
  pose rejected one.
- **Warp**: the frame's pose projects each point and the ends of its patch axes; the
  two pixel steps give the patch's affine map into the frame, and the patch is warped
  by it (the plane through the point facing the exploration camera: a wall seen from a
  little aside is nearly that). A point whose map scales the patch by less than half or
  more than twice, or mirrors it, is not measured (seen from too far from where it was).
- **Align**: the warped patches, brought to the frame's brightness and contrast, are
  aligned at the predicted pixels by one Lucas-Kanade call over a mosaic of them
  (:func:`vbn_common.patch_alignment.align_patches`); an alignment more than
  ``MAX_SHIFT_DEG`` from the prediction, or whose patch then correlates with the frame
  below ``MIN_CORRELATION``, fails.
- **Judge**: a point the refined pose puts more than ``absolute_threshold_px`` from its
  measurement is not searched for ``redetect_cooldown`` frames.

Each measurement is the 3-D point's own pixel (the patch's centre is its reprojection in
the exploration image), so measurements do not drift and are not tied to where SIFT
found the point in the frame.
"""
from __future__ import annotations

import numpy as np

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.scene_tracks import MAX_SHIFT_DEG, SceneTracks
from vbn_common.patch_alignment import align_patches, patch_maps

__all__ = ['MIN_CORRELATION', 'PatchTracks', 'affine_maps', 'scene_tracker']

#: Least normalised correlation of an aligned patch with the frame.
MIN_CORRELATION = 0.75
#: Scale of a patch's warp outside which a point is not measured.
_SCALES = (0.5, 2.0)


def scene_tracker(index: DatabaseIndex, config: LocalizerConfig, detector: object
                  ) -> SceneTracks:
    """Return the scene points' tracker: by their patches when the database has them."""
    if config.scene_tracks > 0 and index.database.points.has_patches:
        return PatchTracks(index, config, detector)
    return SceneTracks(index, config, detector)


def affine_maps(index: DatabaseIndex, camera_pose: np.ndarray, xyz: np.ndarray,
                axes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project points and their patch axes by a camera pose.

    Args:
        index: The database index (the frame camera).
        camera_pose: ``(x, y, yaw)`` of the camera, or ``(x, y, yaw, pitch, roll, dz)``
            with the frame's tilt and height offset (:meth:`.DatabaseIndex.project_points`).
        xyz: ``(n, 3)`` the points.
        axes: ``(n, 2, 3)`` their patch axes (one patch pixel right, one down).

    Returns:
        ``(uv (n, 2), maps (n, 2, 2), ok (n,))``: each point's pixel, the frame pixels one
        patch pixel right (column 0) and down (column 1) moves to, and whether the point
        and both axis ends project.
    """
    n = len(xyz)
    ends = np.concatenate([xyz, xyz + axes[:, 0], xyz + axes[:, 1]])
    uv, ok = index.project_points(camera_pose, ends)
    uv, ok = uv.reshape(3, n, 2), ok.reshape(3, n).all(axis=0)
    camera = index.frame_camera
    maps = patch_maps(uv, camera.width if camera.kind == 'panoramic' else None)
    return uv[0], maps, ok


class PatchTracks(SceneTracks):
    """Scene points measured by their exploration patches (module docstring).

    Args:
        index: The database index; its scene points have patches.
        config: ``scene_tracks``, ``scene_patch_margin_m``, ``redetect_cooldown``,
            ``absolute_threshold_px``.
        detector: Unused (the interface of :class:`SceneTracks`).
    """

    def __init__(self, index: DatabaseIndex, config: LocalizerConfig, detector: object
                 ) -> None:
        super().__init__(index, config, detector)
        points = index.database.points
        self._stored = points.patches
        self._axes = np.asarray(points.patch_axes, float)
        self._has_patch = points.patch_mask

    def margin_m(self) -> float:
        """How far beyond its images' spread a point is measured from: ``scene_patch_margin_m``."""
        return float(self.config.scene_patch_margin_m)

    # -- measurement ---------------------------------------------------------------
    def measure(self, image: np.ndarray, camera_pose: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(uv (m, 2), xyz (m, 3))``: the points aligned near where the pose puts them.

        ``camera_pose``: planar ``(x, y, yaw)``, or with the frame's tilt and height offset
        ``(x, y, yaw, pitch, roll, dz)`` (:meth:`.DatabaseIndex.project_points`).
        """
        self._measured_rows = np.zeros(0, np.int64)
        self._measured_at = self._frame
        none = np.zeros((0, 2)), np.zeros((0, 3))
        if not self.enabled:
            return none
        pose = np.asarray(camera_pose, float)
        chosen = self._choose(pose, image.shape[1], image.shape[0])
        if not len(chosen):
            self.ids = chosen
            return none
        xyz = self.index.scene_xyz[chosen]
        uv, maps, ok = affine_maps(self.index, pose, xyz, self._axes[chosen])
        det = maps[:, 0, 0] * maps[:, 1, 1] - maps[:, 0, 1] * maps[:, 1, 0]
        scale = np.sqrt(np.abs(det))
        ok &= (det > 0) & (scale >= _SCALES[0]) & (scale <= _SCALES[1])
        rows = np.flatnonzero(ok)
        self.ids = chosen[rows]
        pixel, found = align_patches(image, self._stored[self.ids], uv[rows], maps[rows],
                                     MAX_SHIFT_DEG * self._pixels_per_degree, MIN_CORRELATION)
        self._measured_rows = np.flatnonzero(found)
        self._measured = pixel[found]
        return self._measured, self.index.scene_xyz[self.ids[self._measured_rows]]

    def update(self, image: np.ndarray, camera_pose: np.ndarray, state: np.ndarray | None,
               windows: int) -> None:
        """Keep the points the refined pose explains; cool the others down.

        Args:
            image: The frame (unused: no births).
            camera_pose: Its refined planar camera pose.
            state: ``(x, y, yaw, pitch, roll, dz)`` of the refinement, or None.
            windows: Unused (the patches spend no SIFT window).
        """
        if not self.enabled or self._measured_at != self._frame:
            return
        self.ids = self.ids[self._judged(camera_pose, state)]
        self._measured_rows = np.zeros(0, np.int64)

    # -- helpers ---------------------------------------------------------------------
    def _choose(self, pose: np.ndarray, w: int, h: int) -> np.ndarray:
        """Return the points to measure: last frame's good ones, then new ones by cell."""
        want = int(self.config.scene_tracks)
        kept = self.ids[self._failed[self.ids] <= self._frame - self.config.redetect_cooldown]
        candidates = self._candidates(pose)
        candidates = candidates[self._has_patch[candidates]]
        free = want - len(kept)
        if free <= 0 or not len(candidates):
            return kept[:want]
        new, _ = self._round_the_cells(candidates, kept, pose, w, h, free)
        return np.concatenate([kept, new]).astype(np.int64)
