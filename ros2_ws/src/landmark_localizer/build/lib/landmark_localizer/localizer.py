"""The localizer state machine: ``step(frame) -> estimate`` (thesis Chapter 7).

States:

- ``LOST`` (start-up, kidnapped, or the region's features gone): every frame's SIFT
  features vote for regions (:mod:`.voting`); the best verified candidate starts
  ``TRACKING`` with the features it matched.
- ``TRACKING``: the region's features are tracked (:mod:`.tracking`), the pose is
  solved from its model views (:mod:`.pose`), lost features are re-detected where the
  pose predicts them, and the predicted motion switches region before the features
  fade (:mod:`.switching`). When the features are lost anyway (too few tracked, or the
  solve fails twice, or the pose jumps away from the prediction: kidnapped), the
  image votes among the region graph's neighbours first, then globally.

Where no region verifies, the frame still gets a pose when its matches to the
database's triangulated class points fix one (:mod:`.absolute_pose`, event
``'absolute'``): the state stays LOST and the next frame votes again.

Frames with no trustworthy pose from the images are bridged by the odometry from the
last one, with a covariance that grows with the path (:mod:`.bridging`, event
``'odometry'``), until it is too wide.

Counters (:attr:`Localizer.stats`) separate region changes by prediction from those
after a loss, as the thesis's switching rule is meant to make the second kind rare.
Time going backwards (a bag that loops) resets the state.
"""
from __future__ import annotations

from dataclasses import replace
import logging
import time

import numpy as np

from landmark_db.database import LandmarkDatabase
from landmark_localizer.absolute_pose import absolute_solution
from landmark_localizer.bridging import BridgeModel, OdometryBridge, search_prior
from landmark_localizer.compiled import warm_up
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from landmark_localizer.frames import Estimate, Frame, Stats, exposed
from landmark_localizer.health import RegionHealth
from landmark_localizer.ids import IdTable
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.map_search import MapSearch
from landmark_localizer.points_refinement import SourceBalance, motion_prior, refine_on_points
from landmark_localizer.pose import (
    PoseSolution,
    base_covariance,
    base_pose,
    refine_pose,
    solve_pose,
)
from landmark_localizer.switching import MotionPredictor, TrackedCounts, choose_region
from landmark_localizer.tracking import Tracker, Tracks
from landmark_localizer.voting import Verified, agreeing, refutes, verify, vote
from vbn_common.features import SiftConfig, extract_features_scaled
from vbn_common.geometry.frames import compose_poses

__all__ = ['Estimate', 'Frame', 'Localizer', 'LOST', 'TRACKING']

_LOG = logging.getLogger(__name__)

LOST = 'LOST'
TRACKING = 'TRACKING'
_VOTED = ('vote', 'neighbour_vote', 'global_vote')


class Localizer:
    """Localizes camera frames against a landmark database.

    Args:
        database: The database (or a prepared :class:`DatabaseIndex`).
        config: Settings.

    Example:
        >>> localizer = Localizer(open_database('room.db'))  # doctest: +SKIP
        >>> estimate = localizer.step(Frame(stamp_ns, gray))  # doctest: +SKIP
    """

    def __init__(self, database: LandmarkDatabase | DatabaseIndex,
                 config: LocalizerConfig | None = None) -> None:
        self.index = database if isinstance(database, DatabaseIndex) else \
            DatabaseIndex(database)
        config = config or LocalizerConfig()
        self.config = config
        self.sift = SiftConfig(**{k: v for k, v in self.index.database.info.sift.items()
                                  if k in SiftConfig.__dataclass_fields__})
        self.detector = self.sift.create()
        self.tracker = Tracker(self.index, config, self.detector)
        self._ids = IdTable(self.index.n_classes)  # class-id set operations of a frame
        self.map_search = MapSearch(self.index, config)
        self.predictor = MotionPredictor()
        self.balance = SourceBalance()  # tracked features against scene points
        self.bridge = OdometryBridge()
        self.rng = np.random.default_rng(config.seed)
        warm_up()   # the compiled kernels loaded now, not on the first tracked frames
        self.stats = Stats()
        self.health = RegionHealth()  # per-region landmark failures over the run
        self.state = LOST
        self.region = -1
        self.camera_pose: np.ndarray | None = None
        self.last_stamp: int | None = None
        self.hint: tuple[np.ndarray, float] | None = None
        self._failures = 0
        self._features = None  # this frame's voting features and their nearest classes
        self._scene = None  # ... and their nearest scene points
        self._last_camera: np.ndarray | None = None  # the last published camera pose

    # -- control --------------------------------------------------------------------------
    def reset(self) -> None:
        """Forget the region (and any /initialpose hint): vote globally on the next frame."""
        self.state, self.region, self.camera_pose = LOST, -1, None
        self.hint = None
        self.tracker.reset()
        self.predictor.reset()
        self.bridge.reset()
        self.map_search.reset()
        self._failures, self._handover, self._last_camera = 0, -1, None
        self.stats.resets += 1

    def set_config(self, config: LocalizerConfig) -> None:
        """Use new settings from the next frame on (a node's parameters set at run time).

        Every setting is read per frame; a new ``seed`` restarts the robust solvers'
        random generator. The region, the tracks and the motion history are kept.
        """
        if config.seed != self.config.seed:
            self.rng = np.random.default_rng(config.seed)
        self.config = config
        self.tracker.set_config(config)
        self.map_search.set_config(config)

    def reset_motion(self) -> None:
        """Forget the motion history (odometry restarted); the region is kept."""
        self.predictor.reset()
        self.bridge.reset()

    def set_hint(self, x: float, y: float, radius: float | None = None) -> None:
        """Restrict the next votes to regions near ``(x, y)`` (``/initialpose``)."""
        self.hint = (np.array([x, y], float), radius or self.config.hint_radius_m)
        self.state, self.region = LOST, -1
        self._handover = -1
        self._last_camera = None
        self.tracker.reset()
        self.bridge.reset()

    # -- one frame ------------------------------------------------------------------------
    def step(self, frame: Frame) -> Estimate:
        """Process one frame; return the estimate (never raises on a frame's content)."""
        start = time.perf_counter()
        image = np.asarray(frame.image)
        if image.ndim != 2 or image.dtype != np.uint8 or min(image.shape) < 16:
            raise LocalizerError(f'a frame must be a grey uint8 image, got {image.dtype} '
                                 f'{image.shape}')
        image = exposed(image, self.config.exposure_target)
        frame = replace(frame, image=image)   # every step of the frame sees it exposed
        event = ''
        if self.last_stamp is not None and frame.stamp_ns < self.last_stamp:
            self.reset()
            event = 'reset'
        self.last_stamp = frame.stamp_ns
        self.stats.frames += 1
        self.tracker.next_frame()
        self._features = self._scene = self._absolute_of = self._on_points = None
        solution: PoseSolution | None = None
        tracked = 0
        if self.state == TRACKING:
            solution, tracked, lost = self._track(image, frame)
            if lost:
                event = self._recover(image, frame)
                if self.state == TRACKING:
                    solution, tracked = self._last_solution, len(self.tracker.tracks)
        else:
            event = self._vote_global(image, frame) or event
            if self.state == TRACKING:
                solution, tracked = self._last_solution, len(self.tracker.tracks)
        if event in _VOTED and self.state == TRACKING and solution is not None and \
                self.config.absolute_min_inliers > 0 and not self._on_points:
            # Its matches to the points pin a vote's pose its start did not refine on them.
            solution = self._absolute_polish(image, solution)
        if self.state == LOST and self.config.absolute_min_inliers > 0:
            solution = self._absolute(image, frame)
            if solution is not None:
                tracked = solution.inliers
                event = event or 'absolute'
                self.stats.absolute_poses += 1
        self.tracker.prev_image = image
        return self._estimate(frame, solution, tracked, event, start)

    # -- LOST: voting ---------------------------------------------------------------------
    def _vote_features(self, image: np.ndarray, full: bool = False):  # noqa: ANN202
        """Return this frame's voting features and their nearest classes (computed once).

        At ``vote_scale``, or at full size when ``full`` (and from then on this frame).
        """
        if self._features is None or (full and self._features[2] < 1.0):
            scale = 1.0 if full else self.config.vote_scale
            features = extract_features_scaled(image, scale, self.sift, self.detector)
            nearest = self.index.nearest_classes(features.descriptors, self.config.vote_checks)
            self._features, self._scene = (features, nearest, scale), None
        return self._features[:2]

    def _absolute(self, image: np.ndarray, frame: Frame) -> PoseSolution | None:
        """Return the pose from the class points (once a frame; :func:`.voting.refutes`)."""
        if self._absolute_of is None:
            self._absolute_of = (self._solve_absolute(image, frame),)
        return self._absolute_of[0]

    _absolute_of: tuple[PoseSolution | None] | None = None  # this frame's, once computed

    def _solve_absolute(self, image: np.ndarray, frame: Frame) -> PoseSolution | None:
        features, nearest = self._vote_features(image)
        prior = None
        if self._last_camera is not None and self.last_pose_stamp is not None and \
                (frame.stamp_ns - self.last_pose_stamp) / 1e9 <= self.config.absolute_prior_s:
            prior = self._last_camera   # carried by the odometry, else the velocity
            base = self.predictor.by_odometry(frame.odom)
            v = self.predictor.velocity()
            if base is not None:
                prior = compose_poses(base, self.index.camera_mount)
            elif v is not None:
                prior = prior + v * (frame.stamp_ns - self.last_pose_stamp) / 1e9
        searched = search_prior(self.bridge, frame.stamp_ns, frame.odom, self.config,
                                self.index.camera_mount)   # the odometry's: search near it
        return self.map_search.solve(image, features, nearest, self._scene_matches(features),
                                     self.rng, prior, searched)

    def _scene_matches(self, features):  # noqa: ANN001, ANN202 - nearest scene points
        """Return this frame's matches to the scene points (computed once), or None.

        None when the database holds no scene points (asking again costs nothing then).
        """
        if self._scene is None:
            self._scene = self.index.nearest_scene_points(features.descriptors,
                                                          self.config.vote_checks)
        return self._scene

    def _absolute_polish(self, image: np.ndarray, solution: PoseSolution) -> PoseSolution:
        """Return the vote's solution with an absolute pose it agrees with, if any."""
        features, nearest = self._vote_features(image)
        found = agreeing(solution, absolute_solution(   # found near it, else the frame's own
            self.index, features, nearest, self.config, self.rng, solution.estimate.pose,
            self._scene_matches(features)), self._absolute_of and self._absolute_of[0])
        if found is None:
            return solution
        self._last_solution = polished = replace(solution, estimate=found.estimate,
                                                 two_view=solution.two_view_pose)
        self.camera_pose = found.estimate.pose
        return polished

    def _best_verified(self, image: np.ndarray, allowed: np.ndarray | None
                       ) -> Verified | None:
        best = self._verified(image, allowed, full=False)
        if best is None and self._features is not None and self._features[2] < 1.0:
            # A dim, blurred or changed view leaves too few features at the smaller scale.
            best = self._verified(image, allowed, full=True)
        return best

    def _verified(self, image: np.ndarray, allowed: np.ndarray | None, full: bool
                  ) -> Verified | None:
        features, nearest = self._vote_features(image, full)
        self.stats.votes += 1
        best: Verified | None = None
        for candidate in vote(features, self.index, self.config, allowed, nearest):
            found = verify(features, self.index.regions[candidate.region], self.index,
                           self.config, self.rng)
            if found is not None and self.config.absolute_min_inliers > 0:
                checked = refine_on_points(self.index, found.class_ids, found.uv,
                                           found.solution, self.config, strict=True)
                if checked is None:
                    found = None  # too few class points to confirm it, or they disagree
                else:   # unjudged: the seed itself; judged: the pose the points polished
                    found = replace(found, solution=checked,
                                    judged=checked is not found.solution)
            if found is not None and (best is None or (found.judged, found.solution.inliers)
                                      > (best.judged, best.solution.inliers)):
                best = found   # a vote its points judged first
        return best

    def _start(self, found: Verified, frame: Frame) -> None:
        self.state, self.region, self._handover = TRACKING, found.region, -1
        self.map_search.reset()
        region = self.index.regions[found.region]
        self.tracker.set_region(region)
        tracks = Tracks(found.class_ids, found.uv.astype(np.float32))
        solution = found.solution
        if self.config.vote_scale < 1.0:
            # Voting's keypoints come from the smaller image: put the tracks back on
            # full-size SIFT keypoints and polish the pose on them.
            radius = 1.0 / self.config.vote_scale + 1.0
            tracks = self._reanchor(frame.image, tracks, np.arange(len(tracks)), radius)
            uv = tracks.uv.astype(float)
            polished = refine_pose(self.index, region, tracks.class_ids, uv,
                                   solution.estimate.pose, self.config)
            seed = polished or solution   # which its points polish, as a tracked pose's:
            refined = refine_on_points(   # two views alone took one from 0.9 to 5.9 cm
                self.index, tracks.class_ids, uv, seed, self.config,
                scene=lambda pose: self.tracker.scene.measure(frame.image, pose),
                tracked_weight=self.balance.weight())
            self._on_points = refined is not None and refined is not seed
            solution = refined or solution
        self._last_solution = solution
        self._failures = 0
        self.camera_pose = solution.estimate.pose
        self.predictor.reset()
        # The vote matched some of the region's features; look for the others where
        # the pose puts them (a LOST frame has the time), as a switch does.
        self.tracker.tracks, _ = self._search_missing(
            frame.image, tracks, region, self.camera_pose,
            self.config.switch_redetect, landmark_first=True)

    def _allowed_by_hint(self) -> np.ndarray | None:
        if self.hint is None:
            return None
        xy, radius = self.hint
        # A position hint: every heading there.
        poses = self.index.position_tree.query_ball_point(xy, r=radius)
        if not poses:
            poses = [int(self.index.position_tree.query(xy)[1])]
        return np.unique(self.index.region_poses[:, poses].tocoo().row)

    def _vote_global(self, image: np.ndarray, frame: Frame) -> str:
        found = self._best_verified(image, self._allowed_by_hint())
        if found is None or (not found.judged and
                             refutes(self._absolute(image, frame), found.solution)):
            return ''
        self.hint = None
        self._start(found, frame)
        return 'vote'

    def _recover(self, image: np.ndarray, frame: Frame) -> str:
        """Vote among the neighbours, then globally, once the features are lost."""
        previous = self.region
        neighbours = np.append(self.index.region_graph[previous].indices, previous)
        found = self._best_verified(image, neighbours)
        event = 'neighbour_vote'
        if found is None:
            found = self._best_verified(image, None)
            event = 'global_vote'
        if found is not None and not found.judged and \
                refutes(self._absolute(image, frame), found.solution):
            found = None
        if found is None:
            self.state, self.region, self.camera_pose = LOST, -1, None
            self._handover = -1
            self.tracker.reset()
            self.stats.falls_to_lost += 1
            return 'lost'
        self._start(found, frame)
        if found.region != previous:
            self.stats.lost_switches += 1
        return event

    # -- TRACKING -------------------------------------------------------------------------
    def _predicted_camera(self, frame: Frame) -> np.ndarray | None:
        """Return where the camera is now: the odometry's motion since, else constant velocity.

        Without either (the first frame after a vote, with no odometry) the last pose
        itself, and :func:`.points_refinement.motion_prior` then holds nothing to it.
        """
        self._moving = True
        if self.camera_pose is None:
            return None
        moved = self.predictor.by_odometry(frame.odom)
        if moved is not None:
            return compose_poses(moved, self.index.camera_mount)
        v = self.predictor.velocity()
        if v is None or self.last_pose_stamp is None:
            self._moving = False
            return self.camera_pose
        dt = (frame.stamp_ns - self.last_pose_stamp) / 1e9
        return self.camera_pose + v * dt

    last_pose_stamp: int | None = None
    _moving = True  # the prediction has a motion model behind it
    _last_solution: PoseSolution | None = None

    def _track(self, image: np.ndarray, frame: Frame
               ) -> tuple[PoseSolution | None, int, bool]:
        config = self.config
        region = self.index.regions[self.region]
        tracks = self.tracker.track(image)
        predicted = self._predicted_camera(frame)
        incoming = self.index.regions[self._handover].features if self._handover >= 0 \
            else np.zeros(0, np.int64)
        ids = self._ids
        tracks = tracks.subset(ids.member(tracks.class_ids, region.features)
                               | ids.member(tracks.class_ids, incoming))
        if predicted is not None:
            tracks = self._redetect(image, tracks, region, predicted)
        if ids.member(tracks.class_ids, region.features).sum() < config.min_tracked:
            return None, len(tracks), True
        solution = None
        if predicted is not None:
            solution = refine_pose(self.index, region, tracks.class_ids,
                                   tracks.uv.astype(float), predicted, config, level_gate=True)
        if solution is None:
            solution = solve_pose(self.index, region, tracks.class_ids,
                                  tracks.uv.astype(float), config, self.rng, predicted)
        if solution is not None and self.config.absolute_min_inliers > 0:
            solution = refine_on_points(
                self.index, tracks.class_ids, tracks.uv.astype(float), solution, config,
                motion_prior=None if predicted is None or not self._moving else motion_prior(
                    predicted, self.camera_pose, self._last_solution, config),
                scene=lambda pose: self.tracker.scene.measure(image, pose),
                tracked_weight=self.balance.weight())
        if solution is not None and predicted is not None:
            jump = np.linalg.norm(solution.estimate.pose[:2] - predicted[:2])
            if jump > config.max_jump_m:   # kidnapped, or features slid onto a look-alike
                solution = None
        if solution is None:
            self._failures += 1
            self.tracker.tracks = tracks
            return None, len(tracks), self._failures >= 2
        self._failures = 0
        nearest, _ = self.index.nearest_pose(base_pose(self.index, solution.estimate.pose))
        if self.index.region_contains(region.index, np.array([nearest]))[0]:
            # Evidence on the landmark only inside the region: beyond it, the landmark
            # need not be visible (Section 3.1).
            self.health.observe(region.index, region.landmark, found=solution.inlier_classes)
            if self._handover < 0:
                self._probe_landmark(image, region, solution.estimate.pose)
        # Keep the inliers, and the incoming region's features no model view of this
        # region judged (they are the next region's to judge).
        keep = ids.member(tracks.class_ids, solution.inlier_classes) | \
            ~ids.member(tracks.class_ids, region.view_classes)
        tracks = tracks.subset(keep)
        self.tracker.tracks = tracks
        self.camera_pose = solution.estimate.pose
        self._last_solution = solution
        self.balance.update(solution.point_noise)
        self._maybe_switch(frame, region.index)
        state = None if solution.tilt is None else np.r_[self.camera_pose, solution.tilt]
        self.tracker.scene.update(image, self.camera_pose, state,
                                  config.scene_window_budget - self.tracker.windows)
        return solution, len(tracks), False

    def _probe_landmark(self, image: np.ndarray, region, pose: np.ndarray) -> None:
        """Search untracked landmark features where ``pose`` puts them (:mod:`.health`)."""
        missing = self._ids.difference(region.landmark, self.tracker.tracks.class_ids)
        uv, ok = self.index.project(pose, missing)
        missing, uv = missing[ok], uv[ok]
        count = min(self.config.health_probes, missing.size)
        if count == 0:
            return
        pick = (self._probes + np.arange(count)) % missing.size
        self._probes += count
        found = self.tracker.search(image, missing[pick], uv[pick],
                                    self.config.redetect_radius_px, remember=False)
        self.health.observe(region.index, region.landmark, found=found.class_ids,
                            missed=self._ids.difference(missing[pick], found.class_ids))
        self.tracker.tracks = self.tracker.tracks.merged(found, self._ids)

    _probes = 0  # landmark probes so far (round robin over the untracked ones)

    def _redetect(self, image: np.ndarray, tracks: Tracks, region, predicted: np.ndarray
                  ) -> Tracks:
        """Search lost features where the pose predicts them; re-anchor a few tracks.

        In a handover the incoming region's features take the windows (:meth:`_maybe_switch`).
        """
        if self._handover < 0:
            tracks, _ = self._search_missing(image, tracks, region, predicted,
                                             self.config.redetect_per_frame)
        return self._reanchor(image, tracks, self.tracker.refresh_candidates(tracks), 2.0)

    def _reanchor(self, image: np.ndarray, tracks: Tracks, which: np.ndarray, radius: float
                  ) -> Tracks:
        """Move the tracks ``which`` onto the matching SIFT keypoint within ``radius``."""
        if not len(which):
            return tracks
        again = self.tracker.search(image, tracks.class_ids[which], tracks.uv[which],
                                    radius, remember=False)
        if len(again):
            position = {int(c): i for i, c in enumerate(tracks.class_ids)}
            for c, uv in zip(again.class_ids, again.uv, strict=True):
                tracks.uv[position[int(c)]] = uv
        return tracks

    def _maybe_switch(self, frame: Frame, region: int) -> None:
        """Switch region before the features fade when the motion leads out (7.1).

        Make before break: once the predicted motion leads out of the region, the chosen
        next region's features are searched where the current pose projects them from the
        next frame on, ``ceil(switch_redetect / handover_frames)`` windows per frame in
        place of the re-detection's, while the current region still gives the pose; the
        switch happens once ``switch_redetect`` were searched (or none is left). The last
        of ``handover_frames`` frames, or one where fewer than twice ``min_tracked`` of
        the current region's features remain, searches all that is left and switches: a
        switch rarely costs one frame all its windows (each a SIFT run).
        """
        if self.camera_pose is None:
            return
        config = self.config
        current = base_pose(self.index, self.camera_pose)
        ahead = self.predictor.predict(current, config.predict_horizon_s)
        target = choose_region(self.index, region, current, ahead,
                               config.border_margin,
                               TrackedCounts(self.index, self.tracker.tracks.class_ids))
        if target is None:
            self._handover = -1
            return
        new = self.index.regions[target]
        if target != self._handover:
            self._handover, self._handover_age, self._handover_searched = target, 0, 0
            self.tracker.set_region(new)
            return  # its windows start next frame, in place of the re-detection's
        self._handover_age += 1
        left = config.switch_redetect - self._handover_searched
        current = int(self._ids.member(self.tracker.tracks.class_ids,
                              self.index.regions[region].features).sum())
        urgent = current < 2 * config.min_tracked or \
            self._handover_age >= config.handover_frames
        # The last frame (or a region about to lose its features) searches what is left.
        count = left if urgent else min(left, -(-config.switch_redetect //
                                                config.handover_frames))
        self.tracker.tracks, tried = self._search_missing(
            frame.image, self.tracker.tracks, new, self.camera_pose, count,
            landmark_first=True)
        self._handover_searched += tried
        if not urgent and tried == count and tried < left:
            return  # more to search, time left, and the current region still holds
        tracks = self.tracker.tracks
        self.tracker.tracks = tracks.subset(self._ids.member(tracks.class_ids, new.features))
        self.region, self._handover = target, -1
        self.stats.predicted_switches += 1
        self.bridge.settle()   # the next region's features are where the pose put them
        self._switched = True

    def _search_missing(self, image: np.ndarray, tracks: Tracks, region, pose: np.ndarray,
                        count: int, landmark_first: bool = False) -> tuple[Tracks, int]:
        """Search ``count`` of ``region``'s untracked features where ``pose`` puts them.

        Those searched in vain lately are skipped (the tracker's cool-down); the rest are
        taken landmark features first (a switch, a vote) or in random order (so that no
        lost track is starved). Returns the tracks with those found and how many were
        searched (fewer than ``count`` when fewer are left that the pose projects).
        """
        missing = self._ids.difference(region.features, tracks.class_ids)
        missing = missing[~self.tracker.cooling(missing)]
        if missing.size == 0 or count <= 0:
            return tracks, 0
        uv, ok = self.index.project(pose, missing)
        order = np.flatnonzero(ok)
        if landmark_first:
            order = order[np.argsort(~self._ids.member(missing[order], region.landmark),
                                     kind='stable')]
        else:
            order = order[self.rng.permutation(order.size)]
        order = order[:count]
        found = self.tracker.search(image, missing[order], uv[order],
                                    self.config.redetect_radius_px)
        return tracks.merged(found, self._ids), len(order)

    _switched = False
    _handover, _handover_age, _handover_searched = -1, 0, 0   # the region prepared (-1: none)

    # -- output ---------------------------------------------------------------------------
    def _estimate(self, frame: Frame, solution: PoseSolution | None, tracked: int, event: str,
                  start: float) -> Estimate:
        if self._switched:
            event = event or 'predicted_switch'
            self._switched = False
        pose = cov = camera = two_view = None
        model = BridgeModel.of(self.config)
        if solution is not None and (self.state == TRACKING or solution.views_used == 0):
            est = solution.estimate
            cov_ok = np.all(np.isfinite(est.covariance)) and \
                np.sqrt(max(est.covariance[0, 0], est.covariance[1, 1])) <= \
                self.config.max_position_std_m
            if cov_ok and np.all(np.isfinite(est.pose)):
                seen = base_pose(self.index, est.pose)   # the images' pose drives the state
                self.last_pose_stamp = frame.stamp_ns
                self._last_camera = est.pose
                self.predictor.add(frame.stamp_ns, seen, frame.odom)
                if solution.two_view_pose is not None:
                    two_view = base_pose(self.index, solution.two_view_pose)
                pose, cov, kept = self.bridge.fuse(
                    frame.stamp_ns, seen,
                    base_covariance(est.covariance, est.pose, self.index.camera_mount),
                    frame.odom, model, fresh=event in _VOTED, weak=self.state != TRACKING)
                if kept is not None:
                    self.bridge.anchor(frame.stamp_ns, pose, kept, frame.odom)
                else:   # the images contradict a sharper odometry: it gives the pose, or
                    event = event or ('odometry' if pose is not None else 'withheld')
                if pose is not None:   # what is published: the camera of that pose
                    camera = compose_poses(pose, self.index.camera_mount)
                    self.stats.poses += 1
        bridged = None if pose is not None or event == 'withheld' else self.bridge.bridge(
            frame.stamp_ns, frame.odom, model)
        if bridged is not None:
            pose, cov = bridged
            camera, event = compose_poses(pose, self.index.camera_mount), event or 'odometry'
            self.stats.bridged += 1
        if event:
            self.stats.events[event] = self.stats.events.get(event, 0) + 1
        return Estimate(frame.stamp_ns, self.state, self.region if self.state == TRACKING
                        else -1, pose, cov, camera, tracked, event,
                        time.perf_counter() - start, two_view)
