"""The absolute pose near the odometry's prediction, with the map's patches.

Not in the thesis. Where no region verifies (a changed stretch of the world: its
landmark's posters rehung, a cupboard in front of the rest), the frame's SIFT matches to
the database's scene points give the pose (:mod:`.absolute_pose`), but Lowe's ratio test
against the whole map leaves few right ones: 4 to 11 at the true pose among 50 to 200 on
a hall whose changed stretch takes 17 s to drive through. While the odometry still
predicts the pose (:func:`~landmark_localizer.bridging.search_prior`), the scene points
seen from near the prediction are measured by their exploration patches where it puts
them (:class:`~landmark_localizer.scene_patches.PatchTracks`, as a tracked frame does;
``SEARCHED`` times ``scene_tracks`` points): no ratio test, and nearly every measurement
is right (18 to 29 of 19 to 31 at the frames above, with the prediction 3 cm and half a
degree off; 0.12 to 0.27 px from the points' true projections at the median). They join
the SIFT matches in the same robust solve, refined with the Huber threshold of
``absolute_huber_px`` (0.3 px) instead of the inlier threshold (3 px): the few
measurements 2 to 4 px off (a patch aligned on a look-alike) otherwise pulled the pose 1
to 6 cm while it claimed 1 cm (the hall of seed 1 changed: 97.1 % of the poses within 3
sigma with the 3 px Huber threshold, 99.2 % with 0.3 px; 99.6 % with the SIFT matches
alone, with p95 3.5 cm instead of 1.0).

A database without patches (schema 3 or older) searches with the SIFT matches alone.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from landmark_localizer.absolute_pose import absolute_solution
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.pose import PoseSolution
from landmark_localizer.scene_patches import PatchTracks
from vbn_common.features import ImageFeatures

__all__ = ['SEARCHED', 'MapSearch']

#: Scene points measured near the prediction, in units of ``scene_tracks``.
SEARCHED = 3


class MapSearch:
    """Absolute poses near a prediction, from SIFT matches and measured patches.

    Args:
        index: The database index.
        config: The localizer's settings (``scene_tracks``, ``absolute_*``).
    """

    def __init__(self, index: DatabaseIndex, config: LocalizerConfig) -> None:
        self.index = index
        self.config = config
        self.patches = self._tracker(config)

    def set_config(self, config: LocalizerConfig) -> None:
        """Use new settings (a new patch tracker on a change of scene points or margin)."""
        if (config.scene_tracks > 0) != (self.config.scene_tracks > 0) or \
                config.scene_patch_margin_m != self.config.scene_patch_margin_m:
            self.patches = self._tracker(config)
        elif self.patches is not None:
            self.patches.config = _widened(config)
        self.config = config

    def _tracker(self, config: LocalizerConfig) -> PatchTracks | None:
        if config.scene_tracks <= 0 or not self.index.database.points.has_patches:
            return None
        return PatchTracks(self.index, _widened(config), None)

    def reset(self) -> None:
        """Forget the points measured last (the search resumes elsewhere)."""
        if self.patches is not None:
            self.patches.reset()

    def solve(self, image: np.ndarray, features: ImageFeatures,
              nearest: tuple[np.ndarray, np.ndarray, np.ndarray],
              scene: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
              rng: np.random.Generator, prior: np.ndarray | None,
              searched: tuple[np.ndarray, float, float, int] | None) -> PoseSolution | None:
        """Return the frame's absolute camera pose, or None.

        Args:
            image: The frame (grey, exposed).
            features: Its SIFT features.
            nearest: Their matches to the class points (as
                :func:`~.absolute_pose.absolute_solution` takes them).
            scene: ... and to the scene points, if the database has them.
            rng: Random generator of the robust solve.
            prior: The predicted camera pose, if any.
            searched: ``(camera pose, radius_m, turn_rad, least inliers)`` near the
                odometry's prediction (:func:`~.bridging.search_prior` with the camera
                mount applied), or None: the SIFT matches alone, bounded by ``prior``.
        """
        if searched is None:
            self.reset()
            return absolute_solution(self.index, features, nearest, self.config, rng, prior,
                                     scene)
        pose, radius, turn, need = searched
        if self.patches is None or scene is None:
            return absolute_solution(self.index, features, nearest, self.config, rng, pose,
                                     scene, need, radius, turn)
        self.patches.next_frame()
        uv, _ = self.patches.measure(image, pose)
        found = absolute_solution(self.index, features, nearest, self.config, rng, pose, scene,
                                  need, radius, turn, (uv, self.patches.measured_ids),
                                  self.config.absolute_huber_px)
        if found is None:
            self.patches.reset()
        else:   # keep the points the pose explains for the next frame
            self.patches.update(image, found.estimate.pose, None, 0)
        return found


def _widened(config: LocalizerConfig) -> LocalizerConfig:
    return replace(config, scene_tracks=SEARCHED * config.scene_tracks)

