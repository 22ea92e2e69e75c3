"""Following the region's features from frame to frame (thesis 3.1.4, 7.1).

"While navigating inside a region, the corresponding k features are easily tracked
between the images that the robot sees." :class:`Tracker` follows the current
region's landmark and extra features:

- pyramidal Lucas-Kanade from the previous frame, with a forward-backward check (a
  track whose backward flow misses its start by more than ``lk_max_error_px`` is
  dropped);
- a lost feature is re-detected by descriptor in a window around its predicted pixel
  (the class's point projected from the predicted pose): SIFT in the window, matched
  to the class's descriptors (its representatives and its model-view descriptors);
- a few tracked features per frame, in turn, are re-anchored the same way on the SIFT
  keypoint under them, so Lucas-Kanade drift never accumulates for long (the model
  views hold SIFT keypoint positions, so tracks should too).

The work per frame depends on the number of region features (k plus the extras), not
on the size of the database.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import math

import cv2
from numba import njit
import numpy as np

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.ids import IdTable
from landmark_localizer.index import DatabaseIndex, RegionData
from landmark_localizer.scene_patches import scene_tracker

__all__ = ['Tracker', 'Tracks', 'disc_mask']


@njit(cache=True)
def disc_mask(height: int, width: int, cu: float, cv: float, radius: float) -> np.ndarray:
    """(height, width) uint8 mask: 255 on the pixels within ``radius`` of ``(cu, cv)``.

    OpenCV keeps a keypoint when the mask is set at its rounded pixel, so a disc one
    pixel wider than a search radius keeps every keypoint within that radius.
    """
    mask = np.zeros((height, width), np.uint8)
    for y in range(height):
        dv = (y - cv) ** 2
        for x in range(width):
            if dv + (x - cu) ** 2 <= radius * radius:
                mask[y, x] = 255
    return mask


@njit(cache=True)
def _nearest_keypoint(points: np.ndarray, corner: np.ndarray, descriptors: np.ndarray,
                      reference: np.ndarray, centre: np.ndarray, radius: float
                      ) -> tuple[int, float]:
    """Return the keypoint within ``radius`` of ``centre`` nearest a reference descriptor.

    ``points``: (k, 2) float32 keypoints in a window whose corner is ``corner`` (float32
    image pixels, as ``centre``). Returns the keypoint's row and its descriptor distance
    (to the nearest of ``reference``'s rows), or ``(-1, inf)`` when no keypoint lies
    within ``radius``. Distances of the float32 descriptors, summed in float64.
    """
    best, best_d2 = -1, np.inf
    for i in range(points.shape[0]):
        du = (points[i, 0] + corner[0]) - centre[0]
        dv = (points[i, 1] + corner[1]) - centre[1]
        if math.sqrt(du * du + dv * dv) > radius:
            continue
        for j in range(reference.shape[0]):
            d2 = 0.0
            for k in range(descriptors.shape[1]):
                diff = float(descriptors[i, k]) - float(reference[j, k])
                d2 += diff * diff
            if d2 < best_d2:
                best, best_d2 = i, d2
    return best, math.sqrt(best_d2)


@dataclass
class Tracks:
    """Tracked features: class ids and their pixels in the latest frame.

    Attributes:
        class_ids: (t,) int64.
        uv: (t, 2) float32 pixels.
    """

    class_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.float32))

    def __len__(self) -> int:
        return int(self.class_ids.size)

    def subset(self, keep: np.ndarray) -> Tracks:
        """Return the tracks selected by a boolean mask or index array."""
        return Tracks(self.class_ids[keep], self.uv[keep])

    def merged(self, other: Tracks, ids: IdTable | None = None) -> Tracks:
        """Return these tracks plus ``other``'s classes not tracked yet.

        ``ids``: a table over the class ids (faster than ``np.isin``), if the caller has one.
        """
        new = ~(ids.member(other.class_ids, self.class_ids) if ids is not None
                else np.isin(other.class_ids, self.class_ids))
        return Tracks(np.concatenate([self.class_ids, other.class_ids[new]]),
                      np.concatenate([self.uv, other.uv[new]]).astype(np.float32))


class Tracker:
    """Lucas-Kanade tracking plus re-detection by descriptor.

    Args:
        index: The database index (class descriptors, points, camera).
        config: Tracking settings.
        detector: An OpenCV SIFT detector with the database's settings.
    """

    def __init__(self, index: DatabaseIndex, config: LocalizerConfig, detector: object) -> None:
        self.index = index
        self.config = config
        self.detector = detector
        self.prev_image: np.ndarray | None = None
        self.tracks = Tracks()
        self._refresh_cursor = 0
        self._frame = 0
        # Per class, the frame of its last search in vain (long ago: never).
        self._searched = np.full(index.n_classes, -10**9, np.int64)
        self._ids = IdTable(index.n_classes)
        self._reference: dict[int, np.ndarray] = {}
        self.windows = 0  # SIFT windows searched this frame
        # The scene points measured beside the region's features.
        self.scene = scene_tracker(index, config, detector)
        self.set_config(config)

    def set_config(self, config: LocalizerConfig) -> None:
        """Use new settings from the next frame on (windows, thresholds, scene points)."""
        self.config = config
        old = self.scene.config
        if (config.scene_tracks > 0) != (old.scene_tracks > 0) or \
                config.scene_patch_px != old.scene_patch_px or \
                config.scene_patch_margin_m != old.scene_patch_margin_m:
            self.scene = scene_tracker(self.index, config, self.detector)  # a new birth set
        self.scene.config = config
        window = config.lk_window
        self._lk = dict(winSize=(window, window), maxLevel=config.lk_levels,
                        criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))

    def reset(self) -> None:
        """Forget every track and the previous frame."""
        self.prev_image = None
        self.tracks = Tracks()
        self.scene.reset()

    def set_region(self, region: RegionData) -> None:
        """Prepare the reference descriptors of a region's classes (for re-detection)."""
        index = self.index
        for c in region.features:
            c = int(c)
            if c in self._reference:
                continue
            rows = [index.class_descriptors(c)]
            for view in region.views:
                if c in view.position:
                    rows.append(view.descriptors[view.position[c]][None, :])
            self._reference[c] = np.concatenate(rows).astype(np.float32)

    def track(self, gray: np.ndarray) -> Tracks:
        """Move the tracks from the previous frame into this one (Lucas-Kanade)."""
        tracks = self.tracks
        if self.prev_image is None or len(tracks) == 0:
            return Tracks()
        prev, cur = self.prev_image, gray
        p0 = tracks.uv.reshape(-1, 1, 2).astype(np.float32)
        p1, status, _ = cv2.calcOpticalFlowPyrLK(prev, cur, p0, None, **self._lk)
        back, status_back, _ = cv2.calcOpticalFlowPyrLK(cur, prev, p1, None, **self._lk)
        error = np.linalg.norm((back - p0).reshape(-1, 2), axis=1)
        h, w = cur.shape[:2]
        uv = p1.reshape(-1, 2)
        inside = (uv[:, 0] >= 0) & (uv[:, 0] < w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] < h - 1)
        keep = (status.ravel() == 1) & (status_back.ravel() == 1) & \
            (error < self.config.lk_max_error_px) & inside
        return Tracks(tracks.class_ids[keep], uv[keep].astype(np.float32))

    def next_frame(self) -> None:
        """Count a frame (for the re-detection cool-down)."""
        self._frame += 1
        self.windows = 0
        self.scene.next_frame()

    def cooling(self, class_ids: np.ndarray) -> np.ndarray:
        """(n,) bool: classes searched in vain within the last ``redetect_cooldown`` frames."""
        limit = self._frame - self.config.redetect_cooldown
        return self._searched[np.asarray(class_ids, np.int64)] > limit

    def search(self, gray: np.ndarray, class_ids: np.ndarray, predicted: np.ndarray,
               radius: float, remember: bool = True) -> Tracks:
        """Find classes near predicted pixels: SIFT in a window, matched by descriptor.

        A class not found is not searched again for ``redetect_cooldown`` frames
        (``remember``): a feature hidden behind an obstacle stays hidden for a while,
        and each window costs a SIFT run.
        """
        found_ids, found_uv = [], []
        h, w = gray.shape[:2]
        r = int(round(radius)) + 8  # SIFT needs a margin around the keypoints it finds
        for c, (u, v) in zip(class_ids, predicted, strict=True):
            reference = self._reference.get(int(c))
            if reference is None:
                continue
            x0, x1 = max(0, int(u) - r), min(w, int(u) + r + 1)
            y0, y1 = max(0, int(v) - r), min(h, int(v) + r + 1)
            if x1 - x0 < 16 or y1 - y0 < 16:
                continue
            self.windows += 1
            # Descriptors only of the keypoints near the prediction: the rest of the
            # window is there for the pyramid, and describing it cost most of a search.
            mask = disc_mask(y1 - y0, x1 - x0, float(u - x0), float(v - y0),
                             float(radius) + 1.0)   # one compiled signature
            keypoints, descriptors = self.detector.detectAndCompute(gray[y0:y1, x0:x1], mask)
            if not keypoints or descriptors is None:
                continue
            # The keypoint within the radius whose descriptor is nearest the class's.
            corner = np.array([x0, y0], np.float32)
            best, distance = _nearest_keypoint(cv2.KeyPoint_convert(keypoints), corner,
                                               descriptors, reference,
                                               np.array([u, v], np.float32), float(radius))
            if best >= 0 and distance <= self.config.redetect_max_distance:
                found_ids.append(int(c))
                found_uv.append(np.asarray(keypoints[best].pt, np.float32) + corner)
        if remember:
            class_ids = np.asarray(class_ids, np.int64)
            self._searched[class_ids[~self._ids.member(class_ids, found_ids)]] = self._frame
        if not found_ids:
            return Tracks()
        return Tracks(np.array(found_ids, np.int64), np.array(found_uv, np.float32))

    def refresh_candidates(self, tracks: Tracks) -> np.ndarray:
        """Return the indices of the tracks to re-anchor this frame (round robin)."""
        n = len(tracks)
        if n == 0 or self.config.refresh_per_frame == 0:
            return np.zeros(0, np.int64)
        count = min(n, self.config.refresh_per_frame)
        start = self._refresh_cursor % n
        self._refresh_cursor = start + count
        return (start + np.arange(count)) % n
