"""The localizer core on a synthetic world with exact answers (test_support/localizer_samples)."""
from __future__ import annotations

import math

from hypothesis import given, settings
from hypothesis import strategies as st
from localizer_samples import HEIGHT, project, synthetic_database, wall_points
import numpy as np
import pytest

from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from landmark_localizer.index import DatabaseIndex, RegionData
from landmark_localizer.localizer import TRACKING, Frame, Localizer
from landmark_localizer.matching import grouped_nearest, mutual_matches, squared_distances
from landmark_localizer.pose import PoseSolution, refine_pose, solve_pose
from landmark_localizer.switching import MotionPredictor, choose_region
from landmark_localizer.tracking import Tracks


@pytest.fixture(scope='module')
def world():
    rng = np.random.default_rng(3)
    points = wall_points(rng, 90)
    return points, DatabaseIndex(synthetic_database(rng, points))


def current_tracks(points: np.ndarray, pose: np.ndarray, noise_px: float = 0.0,
                   rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    uv, ok = project(pose, points)
    ids = np.flatnonzero(ok)
    uv = uv[ids]
    if noise_px:
        uv = uv + (rng or np.random.default_rng(0)).normal(0, noise_px, uv.shape)
    return ids.astype(np.int64), uv


def test_index_triangulates_the_classes_and_projects_them_back(world) -> None:
    points, index = world
    np.testing.assert_allclose(index.points, points - [0, 0, HEIGHT], atol=1e-5)
    pose = np.array([2.0, 1.3, 0.7])
    ids, uv = current_tracks(points, pose)
    predicted, ok = index.project(pose, ids)
    assert ok.all()
    np.testing.assert_allclose(predicted, uv, atol=1e-4)
    assert index.spacing == pytest.approx(0.5)
    assert index.regions_of_pose(index.nearest_pose([3.0, 1.5])[0]).tolist() == [0, 1]
    dense = index.region_poses.toarray().astype(bool)
    probe = np.arange(index.region_poses.shape[1])
    for r in range(len(index.regions)):  # CSR slices, the same as the sparse rows
        np.testing.assert_array_equal(index.region_contains(r, probe), dense[r])
    view = index.regions[0].views[0]
    rays = index.view_rays(view)
    np.testing.assert_allclose(rays, index.camera.unproject(view.keypoints))
    assert index.view_rays(view) is rays  # computed once
    for c in (0, 7, index.n_classes - 1):  # the same rows as a scan, in the same order
        np.testing.assert_array_equal(index.class_descriptors(c),
                                      index.descriptors[index.descriptor_class == c])


def test_refine_recovers_the_pose_from_a_rough_prediction(world) -> None:
    points, index = world
    truth = np.array([1.7, 1.1, -0.4])
    ids, uv = current_tracks(points, truth)
    start = truth + np.array([0.06, -0.05, math.radians(2.0)])
    solution = refine_pose(index, index.regions[0], ids, uv, start, LocalizerConfig())
    assert solution is not None and solution.views_used == 3
    np.testing.assert_allclose(solution.estimate.pose, truth, atol=1e-6)
    noisy_ids, noisy_uv = current_tracks(points, truth, 0.5, np.random.default_rng(1))
    noisy = refine_pose(index, index.regions[0], noisy_ids, noisy_uv, start, LocalizerConfig())
    assert np.hypot(*(noisy.estimate.pose[:2] - truth[:2])) < 0.01
    assert abs(noisy.estimate.pose[2] - truth[2]) < math.radians(0.2)
    sd = np.sqrt(np.diag(noisy.estimate.covariance))
    assert 1e-4 < sd[0] < 0.02 and 1e-4 < sd[1] < 0.02


def test_covariance_grows_on_the_line_through_two_views(world) -> None:
    points, index = world
    full = index.regions[0]
    two = RegionData(full.index, full.poses, full.features, full.landmark, full.views[:2])
    a, b = two.views[0].pose[:2], two.views[1].pose[:2]
    off_line = np.array([1.0, 1.9, 0.2])
    on_line = np.array([*(a + 0.4 * (b - a)), 0.2])
    spread = []
    for truth in (off_line, on_line):
        ids, uv = current_tracks(points, truth, 0.3, np.random.default_rng(2))
        sol = refine_pose(index, two, ids, uv, truth, LocalizerConfig())
        assert sol is not None
        spread.append(np.sqrt(np.linalg.eigvalsh(sol.estimate.covariance[:2, :2]).max()))
    assert spread[1] > 5 * spread[0]


def test_closed_form_solve_drops_a_view_with_a_wrong_heading(world) -> None:
    points, index = world
    truth = np.array([2.2, 1.4, 1.1])
    ids, uv = current_tracks(points, truth)
    region = index.regions[0]
    exact = solve_pose(index, region, ids, uv, LocalizerConfig(), np.random.default_rng(0))
    assert exact is not None and exact.views_used == 3
    np.testing.assert_allclose(exact.estimate.pose, truth, atol=1e-4)
    # Corrupt view 2: its keypoints rotated 15 degrees of azimuth (a consistent wrong
    # motion: a heading that disagrees with the two other views).
    bad = region.views[2]
    shifted = bad.keypoints.copy()
    shifted[:, 0] = (shifted[:, 0] + 1024 * 15 / 360) % 1024
    views = (*region.views[:2], type(bad)(bad.pose, bad.class_ids, shifted, bad.descriptors,
                                          bad.position))
    corrupted = RegionData(region.index, region.poses, region.features, region.landmark, views)
    sol = solve_pose(index, corrupted, ids, uv, LocalizerConfig(), np.random.default_rng(0))
    assert sol is not None and sol.views_used == 2
    np.testing.assert_allclose(sol.estimate.pose, truth, atol=1e-3)


def test_switch_before_leaving_the_region(world) -> None:
    _, index = world
    # Region 0 spans x <= 3.5, region 1 x >= 2.5: moving east from x = 3.0 leaves region 0.
    assert choose_region(index, 0, np.array([3.0, 1.5]), np.array([3.6, 1.5]), 1.0, {}) == 1
    assert choose_region(index, 0, np.array([3.0, 1.5]), np.array([2.4, 1.5]), 1.0, {}) is None
    assert choose_region(index, 0, np.array([1.0, 1.5]), np.array([1.3, 1.5]), 1.0, {}) is None


def test_motion_predictor_from_history_and_from_odometry() -> None:
    history = MotionPredictor()
    for i in range(5):
        history.add(i * 10**8, np.array([0.05 * i, 0.0, 0.0]), None)
    np.testing.assert_allclose(history.predict(np.array([0.2, 0.0, 0.0]), 1.0), [0.7, 0, 0],
                               atol=1e-9)
    odom = MotionPredictor()
    # The robot faces +y in map (yaw pi/2) while odometry's frame has it face +x.
    for i in range(5):
        odom.add(i * 10**8, np.array([1.0, 2.0, math.pi / 2]), np.array([0.1 * i, 0.0, 0.0]))
    v = odom.velocity()
    np.testing.assert_allclose(v, [0.0, 1.0, 0.0], atol=1e-9)


def test_matching_by_hand() -> None:
    a = np.array([[0, 0], [10, 0], [0, 10]], np.float32)
    b = np.array([[0, 1], [10, 1], [5, 5], [0, 12]], np.float32)
    pairs = mutual_matches(a, b, ratio=0.9, max_distance=5)
    assert pairs.tolist() == [[0, 0], [1, 1], [2, 3]]
    d2 = squared_distances(a, b)
    best, d1, d_other = grouped_nearest(d2, np.array([0, 1, 1, 2]), 3)
    assert best.tolist() == [0, 1, 2]
    assert d1.tolist() == pytest.approx([1.0, 1.0, 2.0])
    assert d_other[0] == pytest.approx(math.sqrt(50))  # nearest of class 1: (5, 5)


def test_config_refuses_bad_values() -> None:
    with pytest.raises(LocalizerError, match='unknown method'):
        LocalizerConfig(method='nope')
    with pytest.raises(LocalizerError, match='lk_window must be odd'):
        LocalizerConfig(lk_window=20)
    with pytest.raises(LocalizerError, match="unknown localizer setting 'nope'"):
        LocalizerConfig().with_values({'nope': 1})


def test_switch_makes_before_it_breaks(world, monkeypatch) -> None:
    """The next region's windows are spread over the frames before the switch."""
    _, index = world
    loc = Localizer(index, LocalizerConfig(switch_redetect=12, handover_frames=3))
    loc.state, loc.region = TRACKING, 0
    loc.camera_pose = np.array([3.0, 1.5, 0.0])
    for i in range(5):  # heading east at 1 m/s: 0.6 s ahead leaves region 0 (x <= 3.5)
        loc.predictor.add(i * 10**8, np.array([2.6 + 0.1 * i, 1.5, 0.0]), None)
    region0 = index.regions[0]
    loc.tracker.tracks = Tracks(region0.features.copy(),
                                np.zeros((len(region0.features), 2), np.float32))
    searched: list[int] = []

    def search(image, tracks, region, pose, count, landmark_first=False):
        searched.append(count)
        return tracks, count

    monkeypatch.setattr(loc, '_search_missing', search)
    frame = Frame(0, np.zeros((32, 32), np.uint8))
    loc._maybe_switch(frame, 0)
    assert (loc.region, loc._handover, searched) == (0, 1, [])  # decided, no window yet
    loc._maybe_switch(frame, 0)
    loc._maybe_switch(frame, 0)
    assert (loc.region, searched) == (0, [4, 4])  # still region 0, four windows a frame
    loc._maybe_switch(frame, 0)
    assert (loc.region, loc._handover, searched) == (1, -1, [4, 4, 4])
    assert loc.stats.predicted_switches == 1
    # Kept: region 1's features only.
    assert np.isin(loc.tracker.tracks.class_ids, index.regions[1].features).all()


def test_a_region_running_low_switches_at_once(world, monkeypatch) -> None:
    _, index = world
    loc = Localizer(index, LocalizerConfig(switch_redetect=12, handover_frames=3))
    loc.state, loc.region = TRACKING, 0
    loc.camera_pose = np.array([3.0, 1.5, 0.0])
    for i in range(5):
        loc.predictor.add(i * 10**8, np.array([2.6 + 0.1 * i, 1.5, 0.0]), None)
    few = index.regions[0].features[:10]  # fewer than twice min_tracked
    loc.tracker.tracks = Tracks(few.copy(), np.zeros((10, 2), np.float32))
    searched: list[int] = []
    monkeypatch.setattr(loc, '_search_missing',
                        lambda image, tracks, region, pose, count, landmark_first=False:
                        (searched.append(count), (tracks, count))[1])
    frame = Frame(0, np.zeros((32, 32), np.uint8))
    loc._maybe_switch(frame, 0)
    loc._maybe_switch(frame, 0)
    assert (loc.region, searched) == (1, [12])  # every window at once, then the switch


def test_coverage_split_by_the_database_regions(world) -> None:
    from pathlib import Path

    from landmark_localizer.localizer import Estimate
    from vbn_bench.localization.offline import OfflineRun, coverage_split
    from vbn_bench.localization.pose_bags import RunBag

    _, index = world
    stamps = np.array([0, 10**8, 2 * 10**8], np.int64)
    truth = np.array([[1.0, 1.5, 0.0], [2.0, 1.5, 0.0], [20.0, 1.5, 0.0]])  # last: off the map
    poses = [truth[0] + [0.03, 0.0, 0.0], None, truth[2] + [0.0, 0.1, 0.0]]
    estimates = [Estimate(int(s), 'TRACKING', 0, p, None, None, 10, '', 0.0)
                 for s, p in zip(stamps, poses, strict=True)]
    run = RunBag(Path('run'), '/camera', 'sensor_msgs/msg/Image', stamps, [b''] * 3,
                 np.zeros(0, np.int64), np.zeros((0, 3)), stamps, truth, [])
    split = coverage_split(OfflineRun(estimates, np.zeros(3), np.zeros(3), 0.0), run, index)
    assert split['inside']['frames'] == 2 and split['inside']['poses'] == 1
    assert split['inside']['availability'] == pytest.approx(0.5)
    assert split['inside']['translation_median_m'] == pytest.approx(0.03)
    assert split['outside']['frames'] == 1
    assert split['outside']['translation_p95_m'] == pytest.approx(0.1)


def test_heading_pose_space_weighs_a_turn_by_one_sector_as_one_grid_step() -> None:
    import dataclasses

    rng = np.random.default_rng(3)
    db = synthetic_database(rng, wall_points(rng))
    db = dataclasses.replace(db, info=dataclasses.replace(
        db.info, parameters={**db.info.parameters, 'pose_headings': 8}))
    index = DatabaseIndex(db)
    assert index.headings == 8 and index.tree.m == 4
    x, y = index.xy[0]
    # Every stored pose has heading 0: a base pose at 45 degrees is one sector off, as
    # far in the pose space as the next grid position; at 0 degrees it is on the pose.
    pose, distance = index.nearest_pose([x, y, 0.0])
    assert pose == 0 and distance == pytest.approx(0.0, abs=1e-12)
    _, distance = index.nearest_pose([x, y, math.pi / 4])
    assert distance == pytest.approx(index.spacing, rel=1e-9)
    assert index.pose_points(np.array([[x, y, 0.0]])).shape == (1, 4)
    # Within one spacing of (x, y, 0): the pose itself and its lattice neighbours only.
    near = index.poses_near([x, y, 0.0], 1.01 * index.spacing)
    assert 0 in near and np.all(np.linalg.norm(index.xy[near] - index.xy[0], axis=1)
                                <= 1.01 * index.spacing)


def test_a_turn_into_the_next_heading_sector_switches_to_a_region_of_that_sector() -> None:
    """Sectors share no region (the pose graph has no turning edge): a turn must switch."""
    import dataclasses

    from landmark_db.database.model import SampledPoses

    rng = np.random.default_rng(4)
    db = synthetic_database(rng, wall_points(rng))
    xy, n = db.poses.xy, len(db.poses.xy)
    poses = SampledPoses(xy=np.vstack([xy, xy]), yaw=np.r_[np.zeros(n), np.full(n, math.pi / 4)],
                         grid=np.vstack([db.poses.grid, db.poses.grid]),
                         edges=np.vstack([db.poses.edges, db.poses.edges + n]), spacing=0.5)
    first, second = db.regions
    regions = (dataclasses.replace(first, poses=np.arange(n)),          # sector 0, all of it
               dataclasses.replace(second, poses=np.arange(n, 2 * n)))  # sector 1, all of it
    import scipy.sparse as sp
    classes = dataclasses.replace(db.classes, visibility=sp.vstack(
        [db.classes.visibility, db.classes.visibility]).tocsr())
    db = dataclasses.replace(db, poses=poses, regions=regions, classes=classes,
                             info=dataclasses.replace(
        db.info, parameters={**db.info.parameters, 'pose_headings': 8}))
    index = DatabaseIndex(db)
    assert not index.same_sector(0, n) and index.same_sector(0, 1)
    here = np.array([2.0, 1.5, 0.05])
    # Driving straight on in sector 0: region 0 holds the way ahead, no switch.
    assert choose_region(index, 0, here, here + [0.3, 0.0, 0.0], 1.0, {}) is None
    # Turning left by 40 degrees: the predicted pose lies in sector 1, which only region 1
    # holds; no region holds both poses, and the switch goes there before the turn.
    assert choose_region(index, 0, here, here + [0.0, 0.0, math.radians(40)], 1.0, {}) == 1
    # Back the other way from sector 1 into sector 0.
    assert choose_region(index, 1, here + [0, 0, math.pi / 4], here, 1.0, {}) == 0


def test_disc_mask_by_hand() -> None:
    from landmark_localizer.tracking import disc_mask
    mask = disc_mask(5, 7, 3.0, 2.0, 1.0)
    expected = np.zeros((5, 7), np.uint8)
    expected[2, 2:5] = 255
    expected[1:4, 3] = 255
    assert mask.dtype == np.uint8 and np.array_equal(mask, expected)
    assert not disc_mask(4, 4, -10.0, -10.0, 3.0).any()


def test_a_masked_window_keeps_every_keypoint_within_the_radius_and_its_descriptor() -> None:
    # The window search describes only the keypoints near the prediction (a disc mask
    # one pixel wider than the radius): the same keypoints and descriptors as
    # describing the whole window and keeping those within the radius.
    import cv2

    from landmark_localizer.tracking import disc_mask
    from vbn_common.features import SiftConfig
    rng = np.random.default_rng(3)
    image = cv2.GaussianBlur(rng.integers(0, 256, (41, 41)).astype(np.uint8), (0, 0), 1.2)
    detector = SiftConfig().create()
    all_kp, all_desc = detector.detectAndCompute(image, None)
    checked = 0
    for centre in ((20.0, 20.0), (14.5, 25.2), (27.0, 12.0)):
        for radius in (2.0, 6.0, 12.0):
            pts = np.array([k.pt for k in all_kp])
            near = np.linalg.norm(pts - centre, axis=1) <= radius
            kp, desc = detector.detectAndCompute(
                image, disc_mask(41, 41, centre[0], centre[1], radius + 1.0))
            got = np.array([k.pt for k in kp]).reshape(-1, 2)
            keep = np.linalg.norm(got - centre, axis=1) <= radius
            assert np.allclose(got[keep], pts[near])
            assert np.array_equal(desc[keep], all_desc[near]) if near.any() else not keep.any()
            checked += int(near.sum())
    assert checked >= 5


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.integers(0, 10**6))
def test_the_nearest_keypoint_is_the_brute_force_one(seed: int) -> None:
    """Within the radius, the keypoint whose descriptor is nearest any reference row."""
    from landmark_localizer.tracking import _nearest_keypoint

    rng = np.random.default_rng(seed)
    points = rng.uniform(0, 41, (12, 2)).astype(np.float32)
    corner = np.array([100.0, 50.0], np.float32)
    descriptors = rng.integers(0, 120, (12, 128)).astype(np.float32)
    reference = rng.integers(0, 120, (3, 128)).astype(np.float32)
    centre = np.array([120.3, 70.6], np.float32)
    radius = float(rng.uniform(3, 15))
    best, distance = _nearest_keypoint(points, corner, descriptors, reference, centre, radius)
    near = np.linalg.norm(points + corner - centre, axis=1) <= radius
    d = np.sqrt(((descriptors[:, None].astype(float) - reference[None]) ** 2).sum(-1)).min(1)
    if not near.any():
        assert best == -1 and distance == np.inf
        return
    expected = np.flatnonzero(near)[np.argmin(d[near])]
    assert best == expected and distance == pytest.approx(d[expected], rel=1e-12)


def test_a_vote_its_points_could_not_judge_is_refused_where_the_absolute_pose_refutes_it(
        world, monkeypatch) -> None:
    """Judged votes start tracking; an unjudged one only if the frame's absolute pose agrees."""
    from landmark_localizer.voting import Verified
    from vbn_common.geometry.localize import PoseEstimate

    _, index = world

    def solution(x: float) -> PoseSolution:
        return PoseSolution(PoseEstimate(x, 1.5, 0.0, np.eye(3) * 1e-4, 0.5, 0.0, 2, True),
                            np.zeros(0, np.int64), 2, 12, 0.3)

    region = index.regions[0]
    ids = region.features[:12].copy()
    frame = Frame(0, np.zeros((64, 64), np.uint8))
    for judged, voted_x, absolute_x, expected in (
            (False, 1.0, 1.5, ''),         # 50 cm apart at 1 cm each: refuted
            (False, 1.0, 1.01, 'vote'),    # agrees
            (True, 1.0, 1.5, 'vote')):     # judged by its points: the absolute not asked
        loc = Localizer(index, LocalizerConfig())
        found = Verified(0, solution(voted_x), ids, np.full((len(ids), 2), 30.0), judged)
        solved: list[int] = []
        monkeypatch.setattr(loc, '_best_verified', lambda image, allowed, f=found: f)
        monkeypatch.setattr(loc, '_solve_absolute',
                            lambda image, frame, x=absolute_x, s=solved:
                            (s.append(1), solution(x))[1])
        assert loc._vote_global(frame.image, frame) == expected
        assert loc.state == (TRACKING if expected else 'LOST')
        assert len(solved) == (0 if judged else 1)
        loc._absolute(frame.image, frame)   # once a frame: not again if the vote asked
        assert len(solved) == 1


def test_refuted_votes_leave_the_frames_lost_and_the_absolute_pose_is_solved_once_a_frame(
        world, monkeypatch) -> None:
    """LOST frames and a lost track alike: an unjudged vote the absolute pose refutes is
    not started from, and each frame solves its absolute pose once (then publishes it)."""
    from landmark_localizer.voting import Verified
    from vbn_common.geometry.localize import PoseEstimate

    _, index = world

    def solution(x: float, views: int = 2) -> PoseSolution:   # 0 views: an absolute pose
        return PoseSolution(PoseEstimate(x, 1.5, 0.0, np.eye(3) * 1e-4, 0.5, 0.0, 2, True),
                            np.zeros(0, np.int64), views, 12, 0.3)

    ids = index.regions[0].features[:12].copy()
    unjudged = Verified(0, solution(1.0), ids, np.full((len(ids), 2), 30.0), judged=False)
    loc = Localizer(index, LocalizerConfig())
    solved: list[int] = []
    monkeypatch.setattr(loc, '_best_verified', lambda image, allowed: unjudged)
    monkeypatch.setattr(loc, '_solve_absolute',
                        lambda image, frame: (solved.append(1), solution(1.5, 0))[1])
    image = np.zeros((64, 64), np.uint8)
    for i in range(2):
        estimate = loc.step(Frame(i * 10**8, image))
        assert (loc.state, estimate.event, len(solved)) == ('LOST', 'absolute', i + 1)
        assert estimate.pose is not None
    loc.state, loc.region, loc.camera_pose = TRACKING, 0, np.array([1.5, 1.5, 0.0])
    monkeypatch.setattr(loc, '_track', lambda image, frame: (None, 0, True))   # features lost
    estimate = loc.step(Frame(3 * 10**8, image))
    assert (loc.state, len(solved)) == ('LOST', 3)


def test_a_vote_is_polished_only_by_an_absolute_pose_it_agrees_with(world, monkeypatch) -> None:
    """The absolute pose found near a vote polishes it where the two agree; a look-alike
    70 cm off a vote with a 10 cm spread does not (a changed room): the frame's own
    absolute pose does where it agrees, else the vote stays as it is."""
    import landmark_localizer.localizer as localizer
    from vbn_common.geometry.localize import PoseEstimate

    _, index = world

    def solution(x: float, std: float = 0.01) -> PoseSolution:
        return PoseSolution(PoseEstimate(x, 1.5, 0.0, np.eye(3) * std ** 2, 0.5, 0.0, 2, True),
                            np.zeros(0, np.int64), 2, 12, 0.3)

    voted = solution(1.0, 0.1)
    image = np.zeros((64, 64), np.uint8)
    for near_x, own_x, expected in ((1.02, None, 1.02),    # agrees: polished
                                    (1.7, 1.01, 1.01),     # a look-alike: the frame's own
                                    (1.7, 1.8, 1.0),       # both refute it: the vote
                                    (1.7, None, 1.0)):     # no own pose: the vote
        loc = Localizer(index, LocalizerConfig())
        monkeypatch.setattr(loc, '_vote_features', lambda image, full=False: (None, None))
        monkeypatch.setattr(loc, '_scene_matches', lambda features: None)
        monkeypatch.setattr(localizer, 'absolute_solution',
                            lambda *args, x=near_x, **kwargs: solution(x))
        loc._absolute_of = None if own_x is None else (solution(own_x),)
        polished = loc._absolute_polish(image, voted)
        assert polished.estimate.x == pytest.approx(expected)
        assert (polished is voted) == (expected == 1.0)


def test_a_level_fit_skips_the_tilt_and_a_raised_camera_takes_it(world, monkeypatch) -> None:
    import landmark_localizer.pose as pose_module
    points, index = world
    truth = np.array([1.7, 1.1, -0.4])
    start = truth + np.array([0.03, -0.02, math.radians(1.0)])
    calls = []

    def counting(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        calls.append(1)
        return pose_module.refine_tilted.__wrapped__(*args, **kwargs)

    counting.__wrapped__ = pose_module.refine_tilted
    monkeypatch.setattr(pose_module, 'refine_tilted', counting)
    ids, uv = current_tracks(points, truth, 0.3, np.random.default_rng(4))
    level = refine_pose(index, index.regions[0], ids, uv, start, LocalizerConfig(),
                        level_gate=True)
    assert level is not None and not calls          # 0.3 px of noise: nothing to gain
    assert np.hypot(*(level.estimate.pose[:2] - truth[:2])) < 0.005
    asked = refine_pose(index, index.regions[0], ids, uv, start,
                        LocalizerConfig())               # a vote's polish tries it anyway
    assert len(calls) == 1 and asked is not None
    calls.clear()
    # The camera 5 cm higher than the exploration's (the points 5 cm lower to it).
    ids, uv = current_tracks(points - [0.0, 0.0, 0.05], truth, 0.3, np.random.default_rng(4))
    raised = refine_pose(index, index.regions[0], ids, uv, start, LocalizerConfig(),
                         level_gate=True)
    planar = refine_pose(index, index.regions[0], ids, uv, start,
                         LocalizerConfig(tilt_prior_deg=0.0))
    assert len(calls) == 1 and raised is not None
    assert np.hypot(*(raised.estimate.pose[:2] - truth[:2])) < 0.005
    # Kept level, the same points fit no pose within max_residual_px.
    assert planar is None



def test_every_step_of_a_dim_frame_sees_it_exposed(world, monkeypatch) -> None:
    """A dim frame is brightened once (``exposure_target``), and the vote, a start's
    re-anchoring and measurements and a switch's windows all get that image: a start had
    searched and measured the dim one while the tracked frames used the bright one."""
    from landmark_localizer.frames import Frame
    from vbn_common.images import exposed

    _, index = world
    loc = Localizer(index, LocalizerConfig())
    seen = []
    monkeypatch.setattr(loc, '_vote_global',
                        lambda image, frame: seen.append((image, frame.image)) or '')
    monkeypatch.setattr(loc, '_absolute', lambda image, frame: None)
    dim = np.tile(np.arange(0, 100, dtype=np.uint8), (64, 1))   # 99th percentile 98
    loc.step(Frame(1, dim))
    bright = exposed(dim, LocalizerConfig().exposure_target)
    assert bright.max() > 2 * dim.max()
    (image, frame_image), = seen
    np.testing.assert_array_equal(image, bright)
    np.testing.assert_array_equal(frame_image, bright)
