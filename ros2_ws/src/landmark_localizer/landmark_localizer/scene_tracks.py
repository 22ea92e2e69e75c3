"""Scene points measured in the tracked frames: more geometry for the pose.

Not in the thesis. The thesis poses a frame from the region's k features in two or three
model views (7.4, 7.5), and :func:`~landmark_localizer.points_refinement.refine_on_points`
polishes that pose on the tracked features' class points. Where those features crowd
one side of the image the polished pose is weak across them: on ``room_run`` the worst
regions were 2 to 3 cm off while their points fitted both that pose and the true one
within 0.3 px. The database also holds its scene points (3-D, one SIFT descriptor each,
and since schema 3 where the exploration saw them from). :class:`SceneTracks` measures
some of them in every tracked frame and hands them to the same refinement:

- **Birth**: a scene point the exploration saw from near the current position
  (``seen_from``: within its images' spread plus ``SEEN_MARGIN_M``; SIFT finds a feature
  at the scales it was seen at), projected into the frame by the current pose, is
  searched by SIFT in a small window (``scene_search_deg`` around it) and matched to
  its descriptor; its pixel and a ``scene_patch_px`` square patch around it are kept.
  Births go round the image's cells, emptiest first (a cell counts its tracked points
  and the births this frame tries before it), and only the SIFT windows the frame has
  left (``scene_window_budget`` less those the tracker spent) are spent on them: a frame
  busy with a region change births none.
- **Measure**: every later frame projects each point by the frame's two-view pose and
  aligns the birth patch there (Lucas-Kanade on a mosaic of all patches, one call); an
  alignment more than ``MAX_SHIFT_DEG`` from the prediction fails. A fixed patch does
  not drift the way frame-to-frame tracking does (its pixel stays the SIFT keypoint's);
  it ages with the viewpoint instead, so a point is born again once the camera moved
  ``scene_max_move_m`` from its birth.
- **Prune**: a point the refined pose puts more than ``absolute_threshold_px`` from its
  measurement is dropped and not searched for ``redetect_cooldown`` frames; a point not
  measured in a frame (outside the image, or its alignment failed) is dropped too, with
  no cool-down. A frame with no refinement on points (``absolute_min_inliers`` 0, or no
  pose) neither prunes nor births.

Angles become pixels by the frame camera's pixels per radian, so the windows mean the
same on a panorama (163 px/rad at 1024 px) as on a 640 px pinhole of 90 deg (320).

Measured in docs/localization.md, section "The structure-based peer and scene points in
tracked frames".
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.spatial import cKDTree

from landmark_db.database.points import SEEN_MARGIN_M
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.matching import squared_distances
from landmark_localizer.points_refinement import point_errors
from vbn_common.geometry.camera import pixels_per_radian
from vbn_common.patch_alignment import image_tiles, tile_mosaic

__all__ = ['CELLS', 'MAX_SHIFT_DEG', 'SceneTracks', 'scene_tracks_unavailable']

#: Grid of image cells that births fill evenly (columns, rows).
CELLS = (16, 4)
#: Largest shift of a measurement from the pose's prediction, degrees.
MAX_SHIFT_DEG = 1.4
#: The points searched from a position of the pose space: at most this many, those seen
#: from nearest.
_NEAREST = 400


class SceneTracks:
    """The scene points measured in the current frames (module docstring).

    Args:
        index: The database index (scene points, cameras).
        config: ``scene_*``, ``redetect_max_distance``, ``redetect_cooldown``,
            ``absolute_threshold_px``.
        detector: An OpenCV SIFT detector with the database's settings.
    """

    def __init__(self, index: DatabaseIndex, config: LocalizerConfig, detector: object
                 ) -> None:
        self.index = index
        self.config = config
        self.detector = detector
        points = index.database.points
        self.enabled = config.scene_tracks > 0 and points.has_seen_from
        if self.enabled:
            self._seen_near_places(np.asarray(points.seen_from, float), self.margin_m())
        self._failed = np.full(points.n_points, -10**9, np.int64)
        self._frame = 0
        self._measured_at = -1
        size = int(config.scene_patch_px)
        self._half = size // 2
        self.unavailable = scene_tracks_unavailable(index, config)
        self._lk = dict(winSize=(11, 11), maxLevel=1, flags=cv2.OPTFLOW_USE_INITIAL_FLOW,
                        criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 20, 0.01))
        self.reset()

    def reset(self) -> None:
        """Forget every point (the localizer lost its pose)."""
        size = 2 * self._half + 1
        self.ids = np.zeros(0, np.int64)
        self._patches = np.zeros((0, size, size), np.uint8)
        self._offsets = np.zeros((0, 2), np.float32)   # keypoint within its patch
        self._born_at = np.zeros((0, 2))               # camera position at birth
        self._measured = np.zeros((0, 2))
        self._measured_rows = np.zeros(0, np.int64)

    def __len__(self) -> int:
        return len(self.ids)

    @property
    def measured_ids(self) -> np.ndarray:
        """Scene point rows of the last :meth:`measure`'s measurements, in its order."""
        return self.ids[self._measured_rows]

    @property
    def _pixels_per_degree(self) -> float:
        """Of the run's camera (set after the index, as the first CameraInfo comes)."""
        return math.radians(pixels_per_radian(self.index.frame_camera))

    def next_frame(self) -> None:
        """Count a frame (for the search cool-down)."""
        self._frame += 1

    # -- measurement ---------------------------------------------------------------
    def measure(self, image: np.ndarray, camera_pose: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(uv (m, 2), xyz (m, 3))``: the points found near where the pose puts them."""
        self._measured_rows = np.zeros(0, np.int64)
        self._measured_at = self._frame
        if not self.enabled or not len(self.ids):
            return np.zeros((0, 2)), np.zeros((0, 3))
        uv, visible = self.index.project_points(camera_pose, self.index.scene_xyz[self.ids])
        h, w = image.shape[:2]
        half, size = self._half, 2 * self._half + 1
        corner = np.round(np.nan_to_num(uv)).astype(np.int64) - half
        inside = visible & (corner[:, 0] >= 0) & (corner[:, 1] >= 0) & \
            (corner[:, 0] + size <= w) & (corner[:, 1] + size <= h)
        rows = np.flatnonzero(inside)
        if not len(rows):
            return np.zeros((0, 2)), np.zeros((0, 3))
        cols = int(math.ceil(math.sqrt(len(rows))))
        crops = image_tiles(image, corner[rows], size).astype(np.float32)
        patches = self._patches[rows].astype(np.float32)
        # The birth patch brought to the crop's brightness and contrast (exposure moves).
        mean_p, mean_c = patches.mean(axis=(1, 2)), crops.mean(axis=(1, 2))
        gain = crops.std(axis=(1, 2)) / np.maximum(patches.std(axis=(1, 2)), 1.0)
        patches = (patches - mean_p[:, None, None]) * gain[:, None, None] + \
            mean_c[:, None, None]
        before, now = tile_mosaic(patches, cols), tile_mosaic(crops, cols)
        cell = np.stack([np.arange(len(rows)) % cols, np.arange(len(rows)) // cols], 1) * size
        start = (self._offsets[rows] + cell).astype(np.float32).reshape(-1, 1, 2)
        guess = (uv[rows] - corner[rows] + cell).astype(np.float32).reshape(-1, 1, 2)
        found, status, _ = cv2.calcOpticalFlowPyrLK(before, now, start, guess.copy(),
                                                    **self._lk)
        found = found.reshape(-1, 2)
        good = (status.ravel() == 1) & \
            (np.linalg.norm(found - guess.reshape(-1, 2), axis=1)
             <= MAX_SHIFT_DEG * self._pixels_per_degree)
        rows = rows[good]
        self._measured_rows = rows
        self._measured = (found[good] - cell[good] + corner[rows]).astype(float)
        return self._measured, self.index.scene_xyz[self.ids[rows]]

    # -- after the pose --------------------------------------------------------------
    def update(self, image: np.ndarray, camera_pose: np.ndarray, state: np.ndarray | None,
               windows: int) -> None:
        """Prune the points the pose rejects, then search new ones with ``windows`` windows.

        Args:
            image: The frame.
            camera_pose: Its refined planar camera pose.
            state: ``(x, y, yaw, pitch, roll, dz)`` of the refinement, or None.
            windows: SIFT windows to spend on births this frame.
        """
        if not self.enabled or self._measured_at != self._frame:
            return  # no refinement measured this frame: nothing to judge the points by
        keep = self._judged(camera_pose, state)
        moved = np.linalg.norm(self._born_at - np.asarray(camera_pose[:2]), axis=1)
        keep &= moved <= self.config.scene_max_move_m
        self._subset(keep)
        if windows > 0 and len(self.ids) < self.config.scene_tracks:
            self._birth(image, np.asarray(camera_pose, float),
                        min(windows, self.config.scene_tracks - len(self.ids)))

    def _judged(self, camera_pose: np.ndarray, state: np.ndarray | None) -> np.ndarray:
        """Return ``(len(self),)`` bool: the points measured within the inlier threshold.

        The others measured this frame are not searched for ``redetect_cooldown`` frames.
        """
        keep = np.zeros(len(self.ids), bool)
        if len(self._measured_rows):
            errors = point_errors(self.index, state if state is not None else camera_pose,
                                  self._measured, self.index.scene_xyz[
                                      self.ids[self._measured_rows]])
            ok = errors <= self.config.absolute_threshold_px / self.index.residual_focal
            keep[self._measured_rows[ok]] = True
            self._failed[self.ids[self._measured_rows[~ok]]] = self._frame
        return keep

    def _subset(self, keep: np.ndarray) -> None:
        self.ids, self._patches = self.ids[keep], self._patches[keep]
        self._offsets, self._born_at = self._offsets[keep], self._born_at[keep]
        self._measured_rows = np.zeros(0, np.int64)

    def _candidates(self, camera_pose: np.ndarray) -> np.ndarray:
        """Points seen from near here, nearest first, neither tracked nor cooling down."""
        _, at = self._places.query(np.asarray(camera_pose[:2], float))
        near = self._seen_by[self._seen_starts[at]:self._seen_starts[at + 1]]
        tracked = np.zeros(len(self._failed), bool)
        tracked[self.ids] = True
        return near[(self._failed[near] <= self._frame - self.config.redetect_cooldown)
                    & ~tracked[near]]

    def margin_m(self) -> float:
        """How far beyond its images' spread a point is searched from (SIFT: ``SEEN_MARGIN_M``)."""
        return SEEN_MARGIN_M

    def _seen_near_places(self, seen: np.ndarray, margin: float) -> None:
        """For each position of the pose space, the points seen from near it (once).

        A point qualifies at a position within its images' spread plus ``margin`` of
        their centre; each position keeps its ``_NEAREST`` nearest-seen points.
        """
        places = np.unique(np.round(np.asarray(self.index.xy, float), 6), axis=0)
        self._places = cKDTree(places)
        lists = self._places.query_ball_point(seen[:, :2], seen[:, 2] + margin)
        point = np.repeat(np.arange(len(seen)), [len(x) for x in lists])
        place = np.concatenate([np.asarray(x, np.int64) for x in lists]) if len(point) \
            else np.zeros(0, np.int64)
        distance = np.linalg.norm(places[place] - seen[point, :2], axis=1)
        order = np.lexsort((distance, place))
        place, point = place[order], point[order]
        rank = np.arange(len(place)) - np.searchsorted(place, place)
        keep = rank < _NEAREST
        self._seen_by = point[keep].astype(np.int64)
        self._seen_starts = np.searchsorted(place[keep], np.arange(len(places) + 1))

    def _birth(self, image: np.ndarray, camera_pose: np.ndarray, count: int) -> None:
        h, w = image.shape[:2]
        candidates, uv = self._round_the_cells(self._candidates(camera_pose), self.ids,
                                               camera_pose, w, h, count)
        radius = self.config.scene_search_deg * self._pixels_per_degree
        margin = int(math.ceil(radius)) + 8     # SIFT needs room around its keypoints
        half, size = self._half, 2 * self._half + 1
        born = []
        for j in range(len(candidates)):
            u, v = uv[j]
            x0, x1 = max(0, int(u) - margin), min(w, int(u) + margin + 1)
            y0, y1 = max(0, int(v) - margin), min(h, int(v) + margin + 1)
            point = int(candidates[j])
            self._failed[point] = self._frame
            if x1 - x0 < 16 or y1 - y0 < 16:
                continue
            keypoints, descriptors = self.detector.detectAndCompute(image[y0:y1, x0:x1], None)
            if not keypoints or descriptors is None:
                continue
            pts = np.array([k.pt for k in keypoints], np.float32) + np.array([x0, y0],
                                                                             np.float32)
            close = np.linalg.norm(pts - np.array([u, v], np.float32), axis=1) <= radius
            if not close.any():
                continue
            reference = np.asarray(self.index.database.points.descriptors[point],
                                   np.float32)[None]
            d = np.sqrt(squared_distances(descriptors[close], reference).ravel())
            best = int(np.argmin(d))
            if d[best] > self.config.redetect_max_distance:
                continue
            pixel = pts[close][best]
            cx, cy = int(round(pixel[0])) - half, int(round(pixel[1])) - half
            if cx < 0 or cy < 0 or cx + size > w or cy + size > h:
                continue
            self._failed[point] = -10**9
            born.append((point, image[cy:cy + size, cx:cx + size].copy(),
                         pixel - np.array([cx, cy], np.float32)))
        if born:
            self.ids = np.concatenate([self.ids, [b[0] for b in born]])
            self._patches = np.concatenate([self._patches, np.stack([b[1] for b in born])])
            self._offsets = np.concatenate([self._offsets, np.stack([b[2] for b in born])])
            self._born_at = np.concatenate([self._born_at,
                                            np.repeat(camera_pose[None, :2], len(born), 0)])

    def _round_the_cells(self, candidates: np.ndarray, kept: np.ndarray,
                         camera_pose: np.ndarray, w: int, h: int, count: int
                         ) -> tuple[np.ndarray, np.ndarray]:
        """Return up to ``count`` candidates the pose shows, round the cells, and their pixels.

        Emptiest cells first: a candidate ranks by its cell's ``kept`` points plus the
        candidates of its cell before it (those seen from nearer).
        """
        n = len(candidates)   # the candidates and the kept points in one projection
        uv, visible = self.index.project_points(
            camera_pose, self.index.scene_xyz[np.concatenate([candidates, kept])])
        mine, seen = uv[n:], visible[n:]
        candidates, uv = candidates[visible[:n]], uv[:n][visible[:n]]
        occupied = np.zeros(CELLS[0] * CELLS[1])
        if len(kept):
            np.add.at(occupied, self._cell(mine[seen], w, h), 1)
        cell = self._cell(uv, w, h)
        order = np.argsort(cell, kind='stable')
        before = np.empty(len(cell), np.int64)
        before[order] = np.arange(len(cell)) - np.searchsorted(cell[order], cell[order])
        order = np.argsort(occupied[cell] + before, kind='stable')[:max(count, 0)]
        return candidates[order], uv[order]

    @staticmethod
    def _cell(uv: np.ndarray, w: int, h: int) -> np.ndarray:
        col = np.clip((uv[:, 0] / w * CELLS[0]).astype(np.int64), 0, CELLS[0] - 1)
        row = np.clip((uv[:, 1] / h * CELLS[1]).astype(np.int64), 0, CELLS[1] - 1)
        return col + CELLS[0] * row


def scene_tracks_unavailable(index: DatabaseIndex, config: LocalizerConfig) -> str:
    """Return why ``scene_tracks`` asks for what the database cannot give, or ''."""
    points = index.database.points
    if config.scene_tracks <= 0:
        return ''
    if not points.n_points:
        return ("the database holds no scene points: poses rest on the regions' features "
                'alone (rebuild it with vbn build for scene points)')
    if not points.has_seen_from:
        return ('the database does not say where its scene points were seen from (schema '
                '2): no scene points are measured (rebuild it with vbn build)')
    return ''
