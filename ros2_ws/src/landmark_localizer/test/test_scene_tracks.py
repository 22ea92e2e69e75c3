"""Scene points measured in tracked frames: birth, alignment, pruning, gating."""
from __future__ import annotations

from dataclasses import replace

from localizer_samples import HEIGHT, synthetic_database, wall_points
import numpy as np
import pytest

from landmark_db.database import ScenePoints
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.scene_tracks import SceneTracks, scene_tracks_unavailable
from vbn_common.features import SiftConfig

SIFT = SiftConfig()


def _image(index: DatabaseIndex, pose: np.ndarray, xyz: np.ndarray, gain: float = 1.0
           ) -> np.ndarray:
    """A dark panorama with one bright Gaussian blob (sigma 2 px) at each point's pixel."""
    h, w = index.frame_camera.height, index.frame_camera.width
    image = np.full((h, w), 40.0)
    uv, ok = index.project_points(pose, xyz)
    yy, xx = np.mgrid[0:h, 0:w]
    for u, v in uv[ok]:
        x0, x1, y0, y1 = int(u) - 8, int(u) + 9, int(v) - 8, int(v) + 9
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            continue
        patch = np.exp(-((xx[y0:y1, x0:x1] - u) ** 2 + (yy[y0:y1, x0:x1] - v) ** 2) / 8.0)
        image[y0:y1, x0:x1] += 180.0 * patch
    return np.clip(image * gain, 0, 255).astype(np.uint8)


@pytest.fixture(scope='module')
def world() -> tuple[DatabaseIndex, np.ndarray]:
    """Scene points on the walls, seen from the middle of the room, their descriptors real.

    The descriptors are SIFT's at the blobs of a frame at (3, 1.5, 0.2), so a search
    finds each point where it lies.
    """
    rng = np.random.default_rng(5)
    database = synthetic_database(rng, wall_points(rng, 20))
    xyz = wall_points(np.random.default_rng(6), 50) - [0.0, 0.0, HEIGHT]
    seen = np.column_stack([np.full(50, 3.0), np.full(50, 1.5), np.full(50, 1.0)])
    index = DatabaseIndex(replace(database, points=ScenePoints(
        xyz, np.full(50, -1), np.zeros((50, 128), np.uint8), np.full(50, 3), seen)))
    pose = np.array([3.0, 1.5, 0.2])
    image = _image(index, pose, xyz)
    detector = SIFT.create()
    uv, ok = index.project_points(pose, xyz)
    descriptors = np.zeros((50, 128), np.uint8)
    found = np.zeros(50, bool)
    keypoints, desc = detector.detectAndCompute(image, None)
    pts = np.array([k.pt for k in keypoints])
    for i in np.flatnonzero(ok):
        d = np.linalg.norm(pts - uv[i], axis=1)
        if d.min() < 0.5:
            descriptors[i], found[i] = desc[int(np.argmin(d))], True
    assert found.sum() >= 30
    index = DatabaseIndex(replace(database, points=ScenePoints(
        xyz[found], np.full(found.sum(), -1), descriptors[found], np.full(found.sum(), 3),
        seen[found])))
    return index, xyz[found]


def _measure_then_update(tracks: SceneTracks, image: np.ndarray, pose: np.ndarray,
                         windows: int) -> None:
    """One frame as the localizer runs it: measure, (the pose), prune and birth."""
    tracks.measure(image, pose)
    tracks.update(image, pose, None, windows=windows)


def _tracks(index: DatabaseIndex, **settings) -> SceneTracks:
    settings.setdefault('scene_tracks', 40)
    return SceneTracks(index, LocalizerConfig(**settings), SIFT.create())


def test_born_points_are_measured_where_they_moved_to(world) -> None:
    index, xyz = world
    tracks = _tracks(index, scene_tracks=12)
    pose = np.array([3.0, 1.5, 0.2])
    _measure_then_update(tracks, _image(index, pose, xyz), pose, windows=30)
    assert len(tracks) == 12                         # the cap
    born = tracks.ids.copy()
    # The camera moves 4 cm and turns; the frame is darker (exposure).
    moved = np.array([3.03, 1.52, 0.23])
    frame = _image(index, moved, xyz, gain=0.7)
    uv, points = tracks.measure(frame, moved)
    assert len(uv) >= 10
    # Where SIFT finds the blobs in the new frame (OpenCV's SIFT puts a keypoint about
    # 0.25 px right of and below a blob's centre, in the exploration's keypoints too):
    # the birth patch keeps the measurement on that keypoint, within 0.05 px.
    keypoints = np.array([k.pt for k in SIFT.create().detect(frame, None)])
    gap = np.linalg.norm(keypoints[None] - uv[:, None], axis=2)
    detected = gap.min(axis=1) < 1.0
    assert detected.sum() >= 8
    np.testing.assert_allclose(uv[detected], keypoints[np.argmin(gap, axis=1)][detected],
                               atol=0.05)
    truth, _ = index.project_points(moved, points)
    np.testing.assert_allclose(uv - truth, 0.25, atol=0.12)
    np.testing.assert_array_equal(np.sort(tracks.ids), np.sort(born))


def test_a_measurement_the_pose_rejects_is_dropped(world) -> None:
    index, xyz = world
    tracks = _tracks(index, scene_tracks=8)
    pose = np.array([3.0, 1.5, 0.2])
    image = _image(index, pose, xyz)
    _measure_then_update(tracks, image, pose, windows=20)
    tracks.next_frame()
    uv, points = tracks.measure(image, pose)
    assert len(uv) == len(tracks) == 8
    tracks._measured[0] += [9.0, 0.0]                # one measurement 9 px off
    wrong = tracks.ids[tracks._measured_rows[0]]
    tracks.update(image, pose, None, windows=0)
    assert len(tracks) == 7 and wrong not in tracks.ids
    # ... and it is not searched again during the cool-down.
    assert wrong not in tracks._candidates(pose)


def test_points_are_searched_only_near_where_they_were_seen(world) -> None:
    index, xyz = world
    tracks = _tracks(index)
    assert len(tracks._candidates(np.array([3.0, 1.5, 0.0]))) == len(xyz)
    # Seen from within 1 m of (3, 1.5), plus the margin: none from (0.5, 0.5).
    assert len(tracks._candidates(np.array([0.5, 0.5, 0.0]))) == 0


def test_no_windows_no_births_and_moving_away_forgets(world) -> None:
    index, xyz = world
    tracks = _tracks(index, scene_max_move_m=0.1)
    pose = np.array([3.0, 1.5, 0.2])
    image = _image(index, pose, xyz)
    _measure_then_update(tracks, image, pose, windows=0)
    assert len(tracks) == 0
    _measure_then_update(tracks, image, pose, windows=5)
    assert 1 <= len(tracks) <= 5
    far = pose + [0.2, 0.0, 0.0]                      # moved 0.2 m > scene_max_move_m
    tracks.next_frame()
    tracks.measure(_image(index, far, xyz), far)
    tracks.update(_image(index, far, xyz), far, None, windows=0)
    assert len(tracks) == 0


def test_off_without_seen_from_or_when_disabled(world) -> None:
    index, xyz = world
    pose = np.array([3.0, 1.5, 0.2])
    image = _image(index, pose, xyz)
    old = DatabaseIndex(replace(index.database, points=replace(index.database.points,
                                                               seen_from=None)))
    for tracks in (_tracks(old), _tracks(index, scene_tracks=0)):
        assert not tracks.enabled
        tracks.update(image, pose, None, windows=10)
        assert len(tracks) == 0 and len(tracks.measure(image, pose)[0]) == 0


def test_a_frame_measured_without_points_neither_prunes_nor_births(world) -> None:
    # absolute_min_inliers 0 (no refinement on points) or no pose: measure is not called.
    index, xyz = world
    tracks = _tracks(index, scene_tracks=8)
    pose = np.array([3.0, 1.5, 0.2])
    image = _image(index, pose, xyz)
    tracks.update(image, pose, None, windows=20)
    assert len(tracks) == 0                           # nothing measured: no births
    _measure_then_update(tracks, image, pose, windows=20)
    born = tracks.ids.copy()
    assert len(born) == 8
    tracks.next_frame()
    tracks.update(image, pose, None, windows=20)      # not measured this frame
    np.testing.assert_array_equal(tracks.ids, born)   # kept, none added


def test_births_go_round_the_cells(world) -> None:
    index, xyz = world
    tracks = _tracks(index, scene_tracks=40)
    pose = np.array([3.0, 1.5, 0.2])
    image = _image(index, pose, xyz)
    candidates = tracks._candidates(pose)
    uv, ok = index.project_points(pose, index.scene_xyz[candidates])
    w, h = index.frame_camera.width, index.frame_camera.height
    n_cells = len(np.unique(tracks._cell(uv[ok], w, h)))
    assert n_cells >= 6
    _measure_then_update(tracks, image, pose, windows=6)
    mine, _ = index.project_points(pose, index.scene_xyz[tracks.ids])
    cells = tracks._cell(mine, w, h)
    # Six windows on a frame whose candidates fill six or more cells: one birth a cell
    # (every search finds its blob here).
    assert len(tracks) == 6 and len(np.unique(cells)) == 6


def test_search_radius_is_an_angle(world) -> None:
    index, _ = world
    tracks = _tracks(index)
    f = index.frame_camera.f_az                       # the panorama's pixels per radian
    assert tracks._pixels_per_degree == pytest.approx(f * np.pi / 180)


def test_tracker_rebuilds_its_scene_points_when_switched_on(world) -> None:
    from landmark_localizer.tracking import Tracker

    index, _ = world
    tracker = Tracker(index, LocalizerConfig(scene_tracks=0), SIFT.create())
    assert not tracker.scene.enabled and not tracker.scene.unavailable
    tracker.set_config(LocalizerConfig(scene_tracks=20))
    assert tracker.scene.enabled
    tracker.set_config(LocalizerConfig(scene_tracks=20, scene_patch_px=21))
    assert tracker.scene._half == 10
    tracker.set_config(LocalizerConfig(scene_tracks=0))
    assert not tracker.scene.enabled


def test_a_database_without_seen_from_says_so(world) -> None:
    index, _ = world
    old = DatabaseIndex(replace(index.database, points=replace(index.database.points,
                                                               seen_from=None)))
    assert 'schema 2' in scene_tracks_unavailable(old, LocalizerConfig(scene_tracks=40))
    assert scene_tracks_unavailable(old, LocalizerConfig(scene_tracks=0)) == ''
    assert 'schema 2' in scene_tracks_unavailable(old, LocalizerConfig())     # on by default
    assert scene_tracks_unavailable(index, LocalizerConfig(scene_tracks=40)) == ''
