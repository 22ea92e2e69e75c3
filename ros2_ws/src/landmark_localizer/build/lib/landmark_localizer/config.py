"""Settings of the localizer core, one frozen dataclass (defaults in config/localizer.yaml).

Every field is a ROS parameter of the node under the same name; the YAML file in the
package's ``config/`` repeats the defaults and a test keeps the two equal.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace
import math
from typing import Any

from landmark_localizer.errors import LocalizerError

__all__ = ['LocalizerConfig']


@dataclass(frozen=True)
class LocalizerConfig:
    """How the localizer votes, tracks, switches and solves.

    Attributes:
        method: two-view method, '' to let the database's camera model pick it
            (panoramic_planar, pinhole_planar or general_essential).
        vote_ratio: Lowe's ratio between the best and second-best class of a query
            feature when voting.
        vote_max_distance: largest SIFT distance of a vote.
        vote_scale: the image is resized by this for voting's SIFT (0.5: a fifth of the
            time; the matched features are then re-anchored on full-size keypoints);
            1 votes on the full image.
        vote_checks: FLANN leaves visited per feature when voting (0: exact matching
            against every class descriptor, whose cost grows with the database).
        vote_min_votes: least votes of a candidate region; 0 means the database's k.
        vote_candidates: candidate regions verified geometrically, most votes first.
        verify_ratio: ratio test when matching the current image to a model view.
        min_inliers: least correspondences a model view must keep in a pose solve.
        max_residual_px: largest RMS epipolar error of a model view's solve, pixels (of
            the coarser of the database's and the frame's camera, as every threshold).
        min_tracked: fewer region features tracked than this means the features are
            lost (the thesis's "the expected k features are not all visible").
        lk_window: Lucas-Kanade window, pixels (odd).
        lk_levels: Lucas-Kanade pyramid levels above the image.
        lk_max_error_px: forward-backward disagreement above which a track is dropped.
        redetect_radius_px: half-size of the window searched around a feature's
            predicted position when its track is lost.
        redetect_per_frame: at most this many lost features searched per frame.
        redetect_cooldown: a feature searched in vain is not searched again for this
            many frames.
        switch_redetect: at most this many of the next region's features searched
            for a switch, spread over the frames before it.
        handover_frames: a switch prepares the next region's features over at most
            this many frames (make before break).
        refresh_per_frame: tracked features re-anchored on a SIFT keypoint per frame
            (round robin; bounds Lucas-Kanade drift).
        redetect_max_distance: largest SIFT distance of a re-detected feature.
        predict_horizon_s: how far ahead the motion is predicted for switching.
        border_margin: a prediction closer than this (in pose-grid spacings) to a pose
            outside the region counts as near its border.
        max_jump_m: a pose further than this from the prediction is distrusted:
            the robot may have been kidnapped, so it votes again.
        max_heading_disagreement_deg: a model view whose implied heading of the
            current camera differs from the other views' by more than this is dropped.
        max_position_std_m: poses with a larger position standard deviation are not
            published.
        hint_radius_m: /initialpose restricts voting to regions with a pose this close.
        tilt_prior_deg: the frame's own pitch and roll (vibration, an uneven floor) and
            its height offset are refined with the pose, with this prior standard
            deviation (:mod:`.tilt_refinement`), and kept when they cut the epipolar
            cost to under a third; 0 refines the planar pose only.
        height_prior_m: prior standard deviation of the frame's height offset, metres.
        absolute_min_inliers: where no region verifies, the pose is computed from the
            frame's matches to the database's triangulated class points
            (:mod:`.absolute_pose`) with at least this many inliers (twice this without
            a recent pose to check it against); 0 disables it.
        absolute_ratio: Lowe's ratio of those matches.
        absolute_threshold_px: their inlier threshold, pixels.
        absolute_huber_px: the refinement of a tracked pose on 3-D points weighs a
            residual beyond this many pixels less (Huber); a measurement is good to a few
            tenths of a pixel, so a larger one is mostly a wrong one.
        absolute_min_spread_deg: least spread of the inliers' bearings, degrees (a
            tracked pose refined with the motion prior does not need it).
        absolute_prior_s: a pose at most this old (carried by the motion) bounds the
            absolute pose to ``max_jump_m`` from it.
        absolute_bridged_min_inliers: while the odometry bridges (no region verifies),
            an absolute pose within three standard deviations of the bridge's
            prediction needs only this many inliers (0: the bridge is no prior).
        motion_prior_m: standard deviation of the predicted camera position in the
            refinement of a tracked pose on its classes' points, metres (0: no motion
            prior).
        motion_prior_deg: ... and of its predicted heading, degrees.
        scene_tracks: scene points measured per tracked frame at most, beside the
            region's features, for the refinement on 3-D points (0: none). A database
            of schema 4 measures them by their exploration patches
            (:mod:`landmark_localizer.scene_patches`; 40 on ``room_run`` over DDS: the
            median error 0.25 -> 0.06 cm, p95 1.82 -> 0.30 cm, node latency p50 20 ->
            27 ms; 80 rather than 40: the pinhole room's mean p95 over three seeds 0.358
            -> 0.323 cm, ``room_run``'s 0.146 -> 0.111 cm), an older one by SIFT windows
            (:mod:`landmark_localizer.scene_tracks`).
        scene_patch_margin_m: a scene point measured by its patch is chosen only where
            the camera stands within its exploration images' spread plus this margin,
            metres. Wider than a SIFT search's (``SEEN_MARGIN_M``, 0.15 m: SIFT finds a
            feature at the scales it was seen at): the warp follows the viewpoint, and a
            patch the viewpoint distorts too much fails its scale or correlation check.
        scene_window_budget: SIFT windows a frame may search in all; new scene points
            are searched with what the tracker left (a database without patches).
        scene_search_deg: a new scene point is searched within this angle of where the
            pose projects it, degrees (pixels: times the camera's pixels per radian; a
            database without patches).
        scene_patch_px: side of the patch a scene point is aligned by (odd), pixels (a
            database without patches: the patches of a schema 4 file have their own).
        scene_max_move_m: a scene point is searched anew once the camera moved this
            far from where its patch was taken, metres (a database without patches).
        bridge_std_per_m: frames without a pose from the images are bridged by the
            odometry from the last one (:mod:`landmark_localizer.bridging`): its position
            error per metre driven, along and across (fraction).
        bridge_yaw_deg_per_m: ... its heading error per metre driven, degrees.
        bridge_yaw_std_per_rad: ... its heading error per radian turned (fraction).
        bridge_max_std_m: bridging stops once the position's standard deviation passes
            this, metres (0: no bridging).
        bridge_max_s: ... or this long after the last pose from the images, seconds.
        exposure_target: a frame whose 99th percentile of grey is below this is
            brightened to it before its features are found (an auto-exposure: SIFT's
            contrast threshold is absolute; 0: never).
        health_probes: landmark features of the region, not tracked, searched per
            frame where the pose puts them, to count the region's landmark failures
            (:mod:`landmark_localizer.health`; 0: none).
        seed: random generator seed of the robust solvers.
    """

    method: str = ''
    vote_ratio: float = 0.85
    vote_max_distance: float = 250.0
    vote_scale: float = 0.5
    vote_checks: int = 64
    vote_min_votes: int = 0
    vote_candidates: int = 4
    verify_ratio: float = 0.85
    min_inliers: int = 8
    max_residual_px: float = 1.0
    min_tracked: int = 8
    lk_window: int = 21
    lk_levels: int = 3
    lk_max_error_px: float = 1.0
    redetect_radius_px: float = 12.0
    redetect_per_frame: int = 3
    redetect_cooldown: int = 10
    switch_redetect: int = 12
    handover_frames: int = 3
    refresh_per_frame: int = 4
    redetect_max_distance: float = 280.0
    predict_horizon_s: float = 0.6
    border_margin: float = 1.0
    max_jump_m: float = 0.75
    max_heading_disagreement_deg: float = 3.0
    max_position_std_m: float = 0.5
    hint_radius_m: float = 1.5
    tilt_prior_deg: float = 1.0
    height_prior_m: float = 0.1
    absolute_min_inliers: int = 15
    absolute_ratio: float = 0.8
    absolute_threshold_px: float = 3.0
    absolute_huber_px: float = 0.3
    absolute_min_spread_deg: float = 20.0
    absolute_prior_s: float = 3.0
    absolute_bridged_min_inliers: int = 10
    motion_prior_m: float = 0.02
    motion_prior_deg: float = 1.0
    scene_tracks: int = 80
    scene_patch_margin_m: float = 0.5
    scene_window_budget: int = 10
    scene_search_deg: float = 1.75
    scene_patch_px: int = 31
    scene_max_move_m: float = 0.4
    bridge_std_per_m: float = 0.08
    bridge_yaw_deg_per_m: float = 2.0
    bridge_yaw_std_per_rad: float = 0.05
    bridge_max_std_m: float = 0.15
    bridge_max_s: float = 5.0
    exposure_target: float = 200.0
    health_probes: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, float) and not math.isfinite(value):
                raise LocalizerError(f'{f.name} must be finite, got {value}')
        if self.method not in ('', 'panoramic_planar', 'pinhole_planar', 'general_essential'):
            raise LocalizerError(f'unknown method {self.method!r} (expected panoramic_planar, '
                                 f'pinhole_planar, general_essential or empty)')
        for name in ('vote_ratio', 'verify_ratio', 'vote_scale', 'absolute_ratio'):
            if not 0 < getattr(self, name) <= 1:
                raise LocalizerError(f'{name} must be in (0, 1], got {getattr(self, name)}')
        for name in ('vote_candidates', 'min_inliers', 'min_tracked', 'lk_window',
                     'handover_frames'):
            if getattr(self, name) < 1:
                raise LocalizerError(f'{name} must be >= 1, got {getattr(self, name)}')
        for name in ('absolute_min_inliers', 'absolute_bridged_min_inliers'):
            if getattr(self, name) < 0:
                raise LocalizerError(f'{name} must be >= 0, got {getattr(self, name)}')
        if self.vote_checks < 0:
            raise LocalizerError(f'vote_checks must be >= 0, got {self.vote_checks}')
        if self.lk_window % 2 == 0:
            raise LocalizerError(f'lk_window must be odd, got {self.lk_window}')
        for name in ('scene_tracks', 'scene_window_budget', 'health_probes'):
            if getattr(self, name) < 0:
                raise LocalizerError(f'{name} must be >= 0, got {getattr(self, name)}')
        if self.scene_patch_px < 11 or self.scene_patch_px % 2 == 0:
            raise LocalizerError(f'scene_patch_px must be odd and >= 11, got '
                                 f'{self.scene_patch_px}')
        for name in ('bridge_std_per_m', 'bridge_yaw_deg_per_m', 'bridge_yaw_std_per_rad',
                     'bridge_max_std_m', 'bridge_max_s', 'exposure_target',
                     'scene_patch_margin_m'):
            if getattr(self, name) < 0:
                raise LocalizerError(f'{name} must be >= 0, got {getattr(self, name)}')
        for name in ('scene_search_deg', 'scene_max_move_m', 'absolute_huber_px'):
            if getattr(self, name) <= 0:
                raise LocalizerError(f'{name} must be > 0, got {getattr(self, name)}')

    def as_dict(self) -> dict[str, Any]:
        """Return the settings as a dict (the node's parameters)."""
        return asdict(self)

    def with_values(self, values: dict[str, Any]) -> LocalizerConfig:
        """Return a copy with ``values`` applied; unknown names are an error."""
        known = {f.name for f in fields(self)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise LocalizerError(f'unknown localizer setting {unknown[0]!r}')
        try:
            return replace(self, **values)
        except TypeError as error:
            raise LocalizerError(f'bad localizer setting: {error}') from error
