"""The motion prior's gate in the tracked pose's refinement (``points_refinement``)."""
from __future__ import annotations

import math

import numpy as np
import pytest


def test_points_that_disagree_with_the_prediction_decide_alone(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """One wall 4 m ahead, 60 degrees wide, 0.3 px noise; a prediction 20 cm too near it.

    Kept (the gate turned off), the prediction pulls the pose 6 cm along the line of
    sight; dropped, the points alone put it within 4 cm, inside three of its standard
    deviations. A prediction 1 cm off (within its 2 cm spread) is kept: the gate does
    not change that pose.
    """
    from localizer_samples import AHEAD, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    import landmark_localizer.points_refinement as refinement
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    n = 30
    _, index, uv, ids = wall_ahead(n, -0.9, 3.9)
    truth = AHEAD
    assert len(ids) == n
    uv = uv + np.random.default_rng(8).normal(0, 0.3, (n, 2))
    seed = PoseSolution(PoseEstimate(*(truth + [0.03, -0.02, 0.01]), np.eye(3) * 1e-4, 0.5,
                                     0.0, 2, True), ids, 2, n, 0.3)
    config = LocalizerConfig()
    spread = np.array([0.02, 0.02, math.radians(1.0)])

    def error(found: PoseSolution) -> float:
        return float(np.hypot(*(found.estimate.pose[:2] - truth[:2])))

    far = (truth + [0.2, 0.0, 0.0], spread)
    found = refinement.refine_on_points(index, ids, uv, seed, config, motion_prior=far)
    assert found is not None and found is not seed
    assert refinement._prior_distance(found.estimate.pose, far) > refinement.PRIOR_GATE
    assert error(found) < 0.04
    offset = found.estimate.pose[:2] - truth[:2]
    assert offset @ np.linalg.solve(found.estimate.covariance[:2, :2], offset) < 11.8
    near = (truth + [0.01, 0.0, 0.0], spread)
    kept = refinement.refine_on_points(index, ids, uv, seed, config, motion_prior=near)
    monkeypatch.setattr(refinement, 'PRIOR_GATE', math.inf)
    pulled = refinement.refine_on_points(index, ids, uv, seed, config, motion_prior=far)
    assert error(pulled) > 0.05
    np.testing.assert_array_equal(
        refinement.refine_on_points(index, ids, uv, seed, config, motion_prior=near)
        .estimate.pose, kept.estimate.pose)
    # A measuring function is asked again where the gate drops the prior: first at the
    # state the prior pulled, then at the points' own, where the pose is measured.
    asked = []

    def measure(state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        asked.append(np.array(state, float))
        return np.zeros((0, 2)), np.zeros((0, 3))

    monkeypatch.undo()
    again = refinement.refine_on_points(index, ids, uv, seed, config, motion_prior=far,
                                        scene=measure)
    assert len(asked) == 2
    assert np.hypot(*(asked[1][:2] - truth[:2])) < 0.04 < np.hypot(*(asked[0][:2] - truth[:2]))
    np.testing.assert_allclose(again.estimate.pose, found.estimate.pose, atol=1e-12)
    # A yaw across +-pi is a small offset, not a full turn.
    assert refinement._prior_distance(np.array([0.0, 0.0, math.pi - 0.01]),
                                      (np.array([0.0, 0.0, -math.pi + 0.01]), spread)) < 2.0


def test_the_motion_prior_widens_with_the_motion_and_the_last_poses_covariance() -> None:
    """2 cm and 1 degree at rest; a fifth of a 20 cm step; plus the last pose's spread."""
    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import motion_prior
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    config = LocalizerConfig()
    predicted = np.array([1.0, 2.0, 0.5])
    centre, std = motion_prior(predicted, None, None, config)
    np.testing.assert_allclose(centre, predicted)
    np.testing.assert_allclose(std, [0.02, 0.02, math.radians(1.0)])
    last_pose = predicted - [0.12, 0.16, 0.0]            # 20 cm on: 4 cm
    _, std = motion_prior(predicted, last_pose, None, config)
    np.testing.assert_allclose(std[:2], [0.04, 0.04])
    # A turn across +-pi is a small turn: the heading keeps its configured spread.
    _, std = motion_prior(np.array([0.0, 0.0, math.pi - 0.01]),
                          np.array([0.0, 0.0, -math.pi + 0.01]), None, config)
    assert std[2] == math.radians(1.0)
    cov = np.diag([0.03 ** 2, 0.03 ** 2, math.radians(2.0) ** 2])
    last = PoseSolution(PoseEstimate(*last_pose, cov, 0.5, 0.0, 2, True), np.arange(3), 2, 3,
                        0.3)
    _, std = motion_prior(predicted, last_pose, last, config)
    np.testing.assert_allclose(std, [0.05, 0.05, math.radians(math.sqrt(5.0))])
    assert motion_prior(predicted, None, None,
                        config.with_values({'motion_prior_m': 0.0})) is None


def test_a_prior_carried_from_pose_to_pose_stays_bounded() -> None:
    """A narrow wall (+-0.8 m at 4 m) at 1 px noise, each pose the next one's prior.

    The refined pose is never vaguer than its prior (the residuals scale the rays'
    noise, not the prior's), so the spread carried on settles (about 4 cm) instead of
    growing frame after frame (it reached 54 cm in 8 frames when the whole information
    was scaled).
    """
    from localizer_samples import AHEAD, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import motion_prior, refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    _, index, uv, ids = wall_ahead(30, 0.7, 2.3)
    truth = AHEAD
    config = LocalizerConfig()
    last = None
    spreads = []
    for frame in range(12):
        noisy = uv + np.random.default_rng(frame).normal(0, 1.0, (len(ids), 2))
        seed = PoseSolution(PoseEstimate(*(truth + [0.03, -0.02, 0.01]), np.eye(3) * 1e-4,
                                         0.5, 0.0, 2, True), ids, 2, len(ids), 0.3)
        prior = motion_prior(truth, truth, last, config)
        last = refine_on_points(index, ids, noisy, seed, config, motion_prior=prior)
        assert last is not None and last is not seed
        spread = np.sqrt(np.diag(last.estimate.covariance))
        assert np.all(spread <= prior[1] + 1e-12)
        spreads.append(spread[:2].max())
    assert max(spreads) < 0.05 and spreads[-1] < 1.1 * spreads[-4]
    # A last pose of unknown covariance gives no prior, not a tight one.
    unknown = PoseSolution(PoseEstimate(*truth, np.full((3, 3), np.nan), 0.5, 0.0, 2, True),
                           ids, 2, len(ids), 0.3)
    assert motion_prior(truth, truth, unknown, config) is None


def test_the_source_balance_weighs_the_tracked_features_by_their_measured_errors() -> None:
    from landmark_localizer.points_refinement import BALANCE_RANGE, SourceBalance

    balance = SourceBalance(rate=0.5)
    assert balance.weight() == 1.0                         # nothing measured yet
    balance.update(None)
    balance.update((float('nan'), 1.0))
    assert balance.weight() == 1.0
    balance.update((4.0e-6, 1.0e-6))                       # the first frame: taken as is
    assert balance.weight() == pytest.approx(0.25)
    balance.update((2.0e-6, 1.0e-6))                       # halfway to the new frame's
    assert (balance.tracked, balance.scene) == pytest.approx((3.0e-6, 1.0e-6))
    assert balance.weight() == pytest.approx(1.0 / 3.0)
    for _ in range(40):
        balance.update((1.0e-6, 100.0e-6))                 # scene points far worse
    assert balance.weight() == BALANCE_RANGE[1]
    for _ in range(40):
        balance.update((100.0e-6, 1.0e-6))
    assert balance.weight() == BALANCE_RANGE[0]
    with pytest.raises(ValueError, match='rate'):
        SourceBalance(rate=0.0)


def _seed(ids: np.ndarray):  # noqa: ANN202 - a two-view seed 2 cm off AHEAD
    from localizer_samples import AHEAD

    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate
    return PoseSolution(PoseEstimate(*(AHEAD + [0.02, -0.01, 0.005]), np.eye(3) * 1e-4, 0.5,
                                     0.0, 2, True), ids, 2, len(ids), 0.3)


def test_a_vote_is_judged_by_its_points_or_returned_as_it_is() -> None:
    """The seed object itself comes back where the points cannot judge it (the localizer
    tells an unjudged vote by that); a strict check refuses too few points."""
    from localizer_samples import AHEAD, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points

    config = LocalizerConfig()
    _, index, uv, ids = wall_ahead(30, -0.9, 3.9)                  # 60 degrees wide
    seed = _seed(ids)
    judged = refine_on_points(index, ids, uv, seed, config, strict=True)
    assert judged is not None and judged is not seed
    assert np.hypot(*(judged.estimate.pose[:2] - AHEAD[:2])) < 1e-3
    _, narrow_index, narrow_uv, narrow_ids = wall_ahead(30, 1.3, 1.7)   # 4 degrees
    narrow = _seed(narrow_ids)
    assert refine_on_points(narrow_index, narrow_ids, narrow_uv, narrow, config,
                            strict=True) is narrow
    assert refine_on_points(index, ids[:3], uv[:3], _seed(ids[:3]), config, strict=True) is None


def test_the_tracked_features_weight_and_both_sources_errors() -> None:
    """Tracked features at 0.6 px, scene points at 0.1 px on the same wall.

    The solution reports each source's mean squared error (tracked about 36 times the
    scene's); weighing the tracked ones by that ratio brings the pose nearer the truth
    over ten draws; without scene points the weight changes nothing.
    """
    from localizer_samples import AHEAD, project, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points

    config = LocalizerConfig()
    _, index, uv, ids = wall_ahead(30, -0.9, 3.9)
    rng = np.random.default_rng(5)
    xyz = np.column_stack([np.full(40, 6.0), rng.uniform(-0.9, 3.9, 40),
                           rng.uniform(0.6, 2.0, 40)])
    scene_uv, ok = project(AHEAD, xyz)
    xyz, scene_uv = xyz[ok], scene_uv[ok]
    xyz_stored = xyz.copy()
    xyz_stored[:, 2] -= 1.2   # the index's points are relative to the camera's height
    errors = {1.0: [], 0.05: []}
    for _ in range(10):
        tracked = uv + rng.normal(0, 0.6, uv.shape)
        scene = (scene_uv + rng.normal(0, 0.1, scene_uv.shape), xyz_stored)
        for weight, found in errors.items():
            solution = refine_on_points(index, ids, tracked, _seed(ids), config, scene=scene,
                                        tracked_weight=weight)
            found.append(np.hypot(*(solution.estimate.pose[:2] - AHEAD[:2])))
            if weight == 1.0:
                assert solution.point_noise is not None
                assert solution.point_noise[0] > 10 * solution.point_noise[1]
    assert np.mean(errors[0.05]) < 0.7 * np.mean(errors[1.0])
    alone = [refine_on_points(index, ids, uv + 0.3, _seed(ids), config, tracked_weight=w)
             for w in (1.0, 0.2)]
    np.testing.assert_array_equal(alone[0].estimate.pose, alone[1].estimate.pose)
    assert alone[0].point_noise is None


def test_a_judged_vote_starts_from_the_pose_its_points_polished(monkeypatch) -> None:
    """A two-view vote 2 cm off, confirmed by 30 class points over 60 degrees: the vote
    the localizer starts from carries the polished pose (within a millimetre)."""
    from localizer_samples import AHEAD, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    import landmark_localizer.localizer as localizer
    from landmark_localizer.voting import Candidate, Verified

    _, index, uv, ids = wall_ahead(30, -0.9, 3.9)
    loc = localizer.Localizer(index, LocalizerConfig())
    seed = _seed(ids)
    monkeypatch.setattr(loc, '_vote_features', lambda image, full=False: (None, None))
    monkeypatch.setattr(localizer, 'vote', lambda *args, **kwargs: [Candidate(0, 30)])
    monkeypatch.setattr(localizer, 'verify',
                        lambda *args, **kwargs: Verified(0, seed, ids, uv))
    found = loc._verified(np.zeros((64, 64), np.uint8), None, full=False)
    assert found is not None and found.judged
    assert np.hypot(*(seed.estimate.pose[:2] - AHEAD[:2])) > 0.02
    assert np.hypot(*(found.solution.estimate.pose[:2] - AHEAD[:2])) < 1e-3
    assert found.solution.two_view_pose is not None
    np.testing.assert_allclose(found.solution.two_view_pose, seed.estimate.pose)


def test_a_vote_starts_from_its_points_whatever_its_views_polish_says(monkeypatch) -> None:
    """A judged vote at the truth whose full-size polish on the two model views moves it 5 cm
    (as ``refine_pose`` did on the pinhole room: 0.85 -> 5.91 cm): the start refines the
    polish on the points and takes the points' pose (within a millimetre), and the step
    then leaves it to them (no absolute polish); a polish the points refute falls back to
    the vote's own pose."""
    from localizer_samples import AHEAD, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.frames import Frame
    import landmark_localizer.localizer as localizer
    from landmark_localizer.pose import PoseSolution
    from landmark_localizer.voting import Verified
    from vbn_common.geometry.localize import PoseEstimate

    _, index, uv, ids = wall_ahead(30, -0.9, 3.9)

    def solution(offset: list[float]) -> PoseSolution:
        return PoseSolution(PoseEstimate(*(AHEAD + offset), np.eye(3) * 1e-4, 0.5, 0.0, 2,
                                         True), ids, 2, len(ids), 0.3)
    image = np.zeros((64, 64), np.uint8)
    for moved, expected in (([0.05, -0.03, 0.0], AHEAD), ([0.6, 0.5, 0.3], AHEAD + 0.001)):
        loc = localizer.Localizer(index, LocalizerConfig())
        monkeypatch.setattr(localizer, 'refine_pose',
                            lambda *args, moved=moved, **kwargs: solution(moved))
        voted = Verified(0, solution([0.001, 0.001, 0.001]), ids, uv, judged=True)
        loc._start(voted, Frame(0, image))
        np.testing.assert_allclose(loc.camera_pose, expected, atol=1e-3)
        assert loc._on_points == (expected is AHEAD)


def test_scene_points_are_measured_where_the_tracked_points_put_the_camera() -> None:
    """A two-view seed 8 cm and 2 degrees off (as on a turn of a kidnapped run).

    Given a measuring function, the refinement asks it once, at the pose the tracked
    features' points give (within a millimetre of the truth here, exact rays), not at
    the seed; the scene points it returns join the pose as a measured pair does.
    """
    from localizer_samples import AHEAD, project, wall_ahead

    from landmark_localizer.config import LocalizerConfig
    from landmark_localizer.points_refinement import refine_on_points
    from landmark_localizer.pose import PoseSolution
    from vbn_common.geometry.localize import PoseEstimate

    config = LocalizerConfig()
    _, index, uv, ids = wall_ahead(30, -0.9, 3.9)
    seed = PoseSolution(PoseEstimate(*(AHEAD + [0.06, -0.05, math.radians(2.0)]),
                                     np.eye(3) * 1e-4, 0.5, 0.0, 2, True), ids, 2, len(ids), 0.3)
    rng = np.random.default_rng(3)
    xyz = np.column_stack([np.full(40, 6.0), rng.uniform(-0.9, 3.9, 40),
                           rng.uniform(0.6, 2.0, 40)])
    scene_uv, ok = project(AHEAD, xyz)
    xyz = xyz[ok] - np.array([0.0, 0.0, 1.2])   # relative to the camera's height
    asked = []

    def measure(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        asked.append(np.array(pose, float))
        return scene_uv[ok], xyz

    found = refine_on_points(index, ids, uv, seed, config, scene=measure)
    assert len(asked) == 1 and asked[0].shape == (6,)
    assert np.hypot(*(asked[0][:2] - AHEAD[:2])) < 1e-3
    assert abs(asked[0][2] - AHEAD[2]) < 1e-3
    given = refine_on_points(index, ids, uv, seed, config, scene=(scene_uv[ok], xyz))
    np.testing.assert_allclose(found.estimate.pose, given.estimate.pose, atol=1e-12)
    assert found.point_noise is not None   # both sources measured


def test_points_project_through_the_frames_tilt_and_height() -> None:
    """``project_points`` of a state with tilt and height puts each point where its ray,
    turned by that tilt, meets it (the refinement's own model: zero angular error)."""
    from localizer_samples import AHEAD, wall_ahead

    from landmark_localizer.points_refinement import point_errors

    _, index, _, ids = wall_ahead(30, -0.9, 3.9)
    xyz = index.points[ids]
    state = np.r_[AHEAD, math.radians(1.5), math.radians(-0.8), 0.05]
    uv, ok = index.project_points(state, xyz)
    assert ok.sum() >= 20
    assert np.max(point_errors(index, state, uv[ok], xyz[ok])) < 1e-6   # radians
    level, _ = index.project_points(AHEAD, xyz)
    assert np.max(np.abs(uv[ok] - level[ok])) > 1.0   # the tilt moves them by pixels
    np.testing.assert_allclose(index.project_points(np.r_[AHEAD, 0.0, 0.0, 0.0], xyz)[0][ok],
                               level[ok])
