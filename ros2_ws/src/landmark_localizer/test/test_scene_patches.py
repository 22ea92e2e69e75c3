"""Scene points measured by their exploration patches: exact, robust, judged."""
from __future__ import annotations

from dataclasses import replace

import cv2
from localizer_samples import HEIGHT, synthetic_database, wall_points
import numpy as np
import pytest

from landmark_db.database import ScenePoints
from landmark_localizer.config import LocalizerConfig
from landmark_localizer.errors import LocalizerError
from landmark_localizer.index import DatabaseIndex
from landmark_localizer.map_search import MapSearch
from landmark_localizer.scene_patches import PatchTracks, affine_maps, scene_tracker
from landmark_localizer.scene_tracks import SceneTracks
from vbn_common.features import SiftConfig
from visibility_builder.point_patches import patch_axes

EXPLORED = np.array([3.0, 1.5, 0.2])   # the camera the patches were cut from


def _image(index: DatabaseIndex, pose: np.ndarray, xyz: np.ndarray, gain: float = 1.0,
           offset: float = 0.0) -> np.ndarray:
    """A textured panorama: two blobs of different size at each point, on a dark wall."""
    h, w = index.frame_camera.height, index.frame_camera.width
    image = np.full((h, w), 40.0)
    uv, ok = index.project_points(pose, xyz)
    yy, xx = np.mgrid[0:h, 0:w]
    for u, v in uv[ok]:
        u, v = u + offset, v
        x0, x1, y0, y1 = int(u) - 10, int(u) + 11, int(v) - 10, int(v) + 11
        if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
            continue
        dx, dy = xx[y0:y1, x0:x1] - u, yy[y0:y1, x0:x1] - v
        image[y0:y1, x0:x1] += 160.0 * np.exp(-(dx ** 2 + dy ** 2) / 6.0) + \
            60.0 * np.exp(-((dx - 3) ** 2 + (dy + 2) ** 2) / 3.0)
    return np.clip(image * gain, 0, 255).astype(np.uint8)


@pytest.fixture(scope='module')
def world() -> tuple[DatabaseIndex, np.ndarray]:
    """Scene points on the walls with 15 px patches cut from the frame at EXPLORED."""
    rng = np.random.default_rng(5)
    database = synthetic_database(rng, wall_points(rng, 20))
    xyz = wall_points(np.random.default_rng(6), 50) - [0.0, 0.0, HEIGHT]
    seen = np.column_stack([np.full(50, 3.0), np.full(50, 1.5), np.full(50, 1.0)])
    plain = ScenePoints(xyz, np.full(50, -1), np.zeros((50, 128), np.uint8),
                        np.full(50, 3), seen)
    index = DatabaseIndex(replace(database, points=plain))
    uv, ok = index.project_points(EXPLORED, xyz)
    h, w = index.frame_camera.height, index.frame_camera.width
    ok &= (uv[:, 0] > 12) & (uv[:, 0] < w - 12) & (uv[:, 1] > 12) & (uv[:, 1] < h - 12)
    image = _image(index, EXPLORED, xyz).astype(np.float32)
    patches = np.zeros((50, 15, 15), np.uint8)
    axes = np.full((50, 2, 3), np.nan, np.float32)
    for i in np.flatnonzero(ok):
        patches[i] = np.rint(cv2.getRectSubPix(image, (15, 15), tuple(uv[i])))
    axes[ok] = patch_axes(xyz[ok], np.repeat(EXPLORED[None], ok.sum(), 0), uv[ok],
                          index.frame_camera)
    points = replace(plain, patches=patches, patch_axes=axes)
    assert points.patch_mask.sum() >= 30
    return DatabaseIndex(replace(database, points=points)), xyz


def _tracks(index: DatabaseIndex, **settings) -> PatchTracks:
    settings.setdefault('scene_tracks', 40)
    tracks = scene_tracker(index, LocalizerConfig(**settings), SiftConfig().create())
    assert isinstance(tracks, PatchTracks)
    return tracks


def test_the_affine_map_is_the_projection_of_the_axes(world) -> None:
    index, xyz = world
    axes = np.asarray(index.database.points.patch_axes, float)
    have = index.database.points.patch_mask
    # From where the patches were cut, one patch pixel is one frame pixel.
    _, maps, ok = affine_maps(index, EXPLORED, xyz[have], axes[have])
    assert ok.all()
    np.testing.assert_allclose(maps, np.broadcast_to(np.eye(2), maps.shape), atol=1e-3)
    # Twice as far from a point: half a pixel per patch pixel.
    i = int(np.flatnonzero(have)[0])
    direction = xyz[i, :2] - EXPLORED[:2]
    back = np.r_[xyz[i, :2] - 2 * direction, EXPLORED[2]]
    _, maps, _ = affine_maps(index, back, xyz[i:i + 1], axes[i:i + 1])
    assert abs(np.sqrt(abs(np.linalg.det(maps[0]))) - 0.5) < 0.02


@pytest.mark.parametrize('error', [np.zeros(3), np.array([0.01, -0.008, 0.004])])
def test_points_are_measured_at_their_true_pixel_from_elsewhere(world, error) -> None:
    index, xyz = world
    tracks = _tracks(index)
    # 12 cm away and turned 9 deg, darker; the pose given to measure is the truth or
    # one 1 cm and 0.2 deg off (a two-view seed): the patches still land on the truth.
    moved = np.array([3.1, 1.43, 0.35])
    frame = _image(index, moved, xyz, gain=0.7)
    uv, points = tracks.measure(frame, moved + error)
    assert len(uv) >= 25
    truth, _ = index.project_points(moved, points)
    np.testing.assert_allclose(uv, truth, atol=0.1)
    assert np.median(np.linalg.norm(uv - truth, axis=1)) < 0.05


def test_a_frame_that_does_not_show_the_patches_measures_nothing(world) -> None:
    index, xyz = world
    tracks = _tracks(index)
    flat = np.full((index.frame_camera.height, index.frame_camera.width), 90, np.uint8)
    uv, _ = tracks.measure(flat, EXPLORED)
    assert len(uv) == 0
    # Every blob 6 px right of where the pose puts it (beyond the largest shift, 1.4 deg
    # or 4 px on this panorama): none is measured there either.
    uv, _ = tracks.measure(_image(index, EXPLORED, xyz, offset=6.0), EXPLORED)
    assert len(uv) == 0


def test_a_measurement_the_pose_rejects_cools_down(world) -> None:
    index, xyz = world
    tracks = _tracks(index, scene_tracks=10)
    image = _image(index, EXPLORED, xyz)
    uv, _ = tracks.measure(image, EXPLORED)
    assert len(uv) == 10
    tracks._measured[0] += [9.0, 0.0]                # one measurement 9 px off
    wrong = tracks.ids[tracks._measured_rows[0]]
    tracks.update(image, EXPLORED, None, windows=0)
    assert len(tracks) == 9 and wrong not in tracks.ids
    tracks.next_frame()
    tracks.measure(image, EXPLORED)
    assert wrong not in tracks.ids and len(tracks) == 10   # kept the 9, chose one more


def test_the_tracker_follows_the_database(world) -> None:
    index, _ = world
    config = LocalizerConfig(scene_tracks=40)
    plain = replace(index.database.points, patches=None, patch_axes=None)
    without = DatabaseIndex(replace(index.database, points=plain))
    assert type(scene_tracker(without, config, None)) is SceneTracks
    assert type(scene_tracker(index, replace(config, scene_tracks=0), None)) is SceneTracks
    assert type(scene_tracker(index, config, None)) is PatchTracks


def test_points_with_a_patch_are_measured_from_farther_than_a_sift_search(world) -> None:
    """Seen from within 1 m of (3, 1.5): SIFT searches them up to 1.15 m from there, their
    patches (the warp follows the viewpoint) up to 1 m plus ``scene_patch_margin_m``."""
    from landmark_localizer.tracking import Tracker

    index, xyz = world
    far = np.array([4.0, 0.5, 0.0])        # 1.41 m
    beyond = np.array([1.5, 1.0, 0.0])     # 1.58 m
    sift = SceneTracks(index, LocalizerConfig(scene_tracks=40), None)
    assert len(sift._candidates(far)) == 0
    assert len(_tracks(index)._candidates(far)) == len(xyz)          # 0.5 m by default
    assert len(_tracks(index)._candidates(beyond)) == 0
    assert len(_tracks(index, scene_patch_margin_m=0.3)._candidates(far)) == 0
    tracker = Tracker(index, LocalizerConfig(scene_tracks=40), SiftConfig().create())
    tracker.set_config(LocalizerConfig(scene_tracks=40, scene_patch_margin_m=0.6))
    assert len(tracker.scene._candidates(beyond)) == len(xyz)
    search = MapSearch(index, LocalizerConfig(scene_tracks=40))
    assert len(search.patches._candidates(beyond)) == 0
    search.set_config(LocalizerConfig(scene_tracks=40, scene_patch_margin_m=0.6))
    assert len(search.patches._candidates(beyond)) == len(xyz)
    with pytest.raises(LocalizerError, match='scene_patch_margin_m'):
        LocalizerConfig(scene_patch_margin_m=-0.1)
