"""The structure-based peer: its map's geometry, its matching, its pose."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landmark_localizer.errors import LocalizerError
from vbn_bench.localization.peer import _FACES, PeerConfig, PeerLocalizer, cube_faces
from vbn_bench.localization.peer_map import (
    PeerMap,
    _epipolar_ok,
    _errors,
    _representatives,
    _triangulate,
    world_rays,
)
from vbn_bench.localization.peer_report import peer_table, peer_targets
from vbn_common.features import SiftConfig
from vbn_common.geometry.camera import make_camera
from vbn_common.geometry.frames import BASE_TO_CAMERA_ROTATION

pytest.importorskip('pycolmap')


def _optical(points: np.ndarray, camera_pose: np.ndarray) -> np.ndarray:
    """Points in the optical frame of a level camera at a planar pose."""
    c, s = math.cos(camera_pose[2]), math.sin(camera_pose[2])
    world_from_optical = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ BASE_TO_CAMERA_ROTATION
    return (points - [camera_pose[0], camera_pose[1], 0.0]) @ world_from_optical


def _map(points: np.ndarray, camera, descriptors: np.ndarray | None = None) -> PeerMap:
    rng = np.random.default_rng(1)
    n = len(points)
    desc = rng.integers(0, 255, (n, 128), dtype=np.uint8) if descriptors is None \
        else descriptors
    info = camera.camera_info()
    return PeerMap(points, desc, np.arange(n, dtype=np.int32), np.arange(n),
                   (info.width, info.height, info.distortion_model, info.d, info.k),
                   np.eye(3), np.array([0.1, 0.0, 0.0]), SiftConfig(), 2)


def test_cube_faces_are_rotations_and_keep_every_ray() -> None:
    for face in _FACES:
        assert np.allclose(face @ face.T, np.eye(3)) and np.isclose(np.linalg.det(face), 1)
    rng = np.random.default_rng(0)
    rays = rng.normal(size=(500, 3))
    rays /= np.linalg.norm(rays, axis=1, keepdims=True)
    face, pixel = cube_faces(rays, 200.0)
    assert set(face.tolist()) == set(range(6))
    assert np.all((pixel >= 0) & (pixel <= 400))          # inside the 2f x 2f face
    local = np.column_stack([(pixel - 200.0) / 200.0, np.ones(len(rays))])
    back = np.einsum('nji,nj->ni', _FACES[face], local)   # face_from_camera^T
    back /= np.linalg.norm(back, axis=1, keepdims=True)
    np.testing.assert_allclose(back, rays, atol=1e-12)


@pytest.mark.parametrize('kind', ['panoramic', 'pinhole', 'fisheye'])
def test_pose_from_exact_matches_is_exact(kind: str) -> None:
    camera = make_camera(kind)
    rng = np.random.default_rng(2)
    truth = np.array([1.2, -0.4, 0.7])
    points = rng.uniform([-4, -4, -0.8], [4, 4, 1.2], (400, 3))
    uv, seen = camera.project(_optical(points, truth))
    peer = PeerLocalizer(_map(points[seen], camera), camera)
    rays = camera.unproject(uv[seen])
    solved = peer._solve(rays, np.arange(len(rays)), np.arange(len(rays)))
    assert solved is not None
    pose, inliers = solved
    assert inliers == len(rays)
    np.testing.assert_allclose(pose, truth, atol=1e-6)


def test_pose_from_noisy_matches_with_outliers_is_close() -> None:
    camera = make_camera('pinhole')
    rng = np.random.default_rng(3)
    truth = np.array([0.5, 0.3, -0.2])
    points = rng.uniform([-4, -4, -0.8], [4, 4, 1.2], (600, 3))
    uv, seen = camera.project(_optical(points, truth))
    uv, points = uv[seen], points[seen]
    uv = uv + rng.normal(0, 0.3, uv.shape)
    wrong = rng.random(len(uv)) < 0.3                       # 30 % outliers
    uv[wrong] = rng.uniform([0, 0], [640, 480], (int(wrong.sum()), 2))
    peer = PeerLocalizer(_map(points, camera), camera)
    pose, inliers = peer._solve(camera.unproject(uv), np.arange(len(uv)), np.arange(len(uv)))
    assert abs(inliers - (~wrong).sum()) <= 0.05 * len(uv)
    assert np.linalg.norm(pose[:2] - truth[:2]) < 0.005 and abs(pose[2] - truth[2]) < 1e-3


def test_global_matching_keeps_distinct_nearest_and_drops_ambiguous() -> None:
    camera = make_camera('panoramic')
    base = np.zeros((3, 128), np.uint8)
    base[0, :8], base[1, 8:16], base[2, 16:24] = 200, 200, 200
    peer = PeerLocalizer(_map(np.zeros((3, 3)), camera, base), camera)
    query = base.copy()
    query = np.vstack([query, (base[0].astype(int) + base[1]) // 2])  # halfway: ambiguous
    rows, points = peer._match_global(query.astype(np.uint8))
    assert rows.tolist() == [0, 1, 2] and points.tolist() == [0, 1, 2]


def test_tracking_matches_near_the_prediction_only() -> None:
    camera = make_camera('pinhole')
    rng = np.random.default_rng(4)
    truth = np.array([0.0, 0.0, 0.1])
    points = rng.uniform([-4, -4, -0.8], [4, 4, 1.2], (300, 3))
    uv, seen = camera.project(_optical(points, truth))
    points, uv = points[seen], uv[seen]
    desc = rng.integers(0, 255, (len(points), 128), dtype=np.uint8)
    peer = PeerLocalizer(_map(points, camera, desc), camera, PeerConfig(mode='tracking'))
    shuffled = rng.permutation(len(points))
    keys = uv[shuffled] + rng.normal(0, 0.5, uv.shape)
    rays = camera.unproject(keys)
    rows, found = peer._match_near(rays, desc[shuffled], truth)
    assert len(rows) == len(points)
    np.testing.assert_array_equal(found, shuffled[rows])
    # A prediction 1 m off projects the points elsewhere: few candidates, few matches.
    rows, _ = peer._match_near(rays, desc[shuffled], truth + [1.0, 0.0, 0.3])
    assert len(rows) < 0.2 * len(points)


def test_bad_settings_are_refused() -> None:
    with pytest.raises(LocalizerError, match='peer mode'):
        PeerConfig(mode='nearest')
    with pytest.raises(LocalizerError, match='descriptors'):
        PeerConfig(descriptors='some')


def test_map_geometry_by_hand() -> None:
    # Two cameras 1 m apart looking along +x (yaw 0) at a point 3 m ahead.
    point = np.array([3.0, 0.5, 0.2])
    poses = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    origins = np.column_stack([poses[:, :2], np.zeros(2)])
    dirs = []
    for pose in poses:
        ray = _optical(point[None], pose)[0]
        dirs.append(world_rays(pose, (ray / np.linalg.norm(ray))[None])[0])
    dirs = np.array(dirs)
    np.testing.assert_allclose(dirs[0], (point - origins[0]) / np.linalg.norm(point - origins[0]))
    track = np.array([0, 0])
    np.testing.assert_allclose(_triangulate(track, origins, dirs, 1)[0], point, atol=1e-12)
    assert np.all(_errors(point[None], track, origins, dirs) < 1e-9)
    threshold = 1e-3
    assert _epipolar_ok(dirs[:1], dirs[1:], origins[0], origins[1], threshold).all()
    off = dirs[1] + [0.0, 0.0, 0.02]
    assert not _epipolar_ok(dirs[:1], (off / np.linalg.norm(off))[None], origins[0],
                            origins[1], threshold).any()
    behind = -dirs[1]
    assert not _epipolar_ok(dirs[:1], behind[None], origins[0], origins[1], threshold).any()


def test_representative_is_the_most_central_descriptor() -> None:
    desc = np.array([[0] * 128, [10] * 128, [4] * 128, [50] * 128], np.uint8)
    point_of = np.array([0, 0, 0, 1])
    assert _representatives(desc, point_of, 2).tolist() == [2, 3]


def _fig(median: float, p95: float, heading: float, latency: float, size: float,
         peer: dict | None = None) -> dict:
    return {'frames': 10, 'availability': 1.0, 'size_bytes': size, 'peer': peer,
            'evo': {'translation_median_m': median, 'translation_p95_m': p95,
                    'translation_max_m': 2 * p95, 'heading_median_deg': heading},
            'latency': {'p50': latency, 'tracking_p95': latency}}


def test_peer_table_and_targets_by_hand() -> None:
    peer = {'map_bytes': 9e6, 'compact_bytes': 3e6, 'mode': 'tracking'}
    runs = {'room_run': _fig(0.0008, 0.0025, 0.01, 0.008, 0.9e6),
            'peer_tracking_room_run': _fig(0.0005, 0.0012, 0.005, 0.1, 9e6, peer)}
    checks = {label: (value, limit, at_most) for label, value, limit, at_most
              in peer_targets(runs)}
    assert checks["room_run TRACKING p95 / the peer's"][0] == pytest.approx(0.08)
    assert checks["room_run database / the peer's compact map"][0] == pytest.approx(0.3)
    assert all(v <= lim for v, lim, at_most in checks.values())
    lines = peer_table(runs)
    assert any('ours / peer tracking | - | 1.60 / 2.08 | 2.00 | 0.08 / 0.08 | 0.30' in line
               for line in lines)
    assert peer_targets({'room_run': runs['room_run']}) == []


def _fake_exploration(monkeypatch, n_features: int) -> None:
    """Two exploration images 0.5 m apart whose SIFT features are random (none match)."""
    from types import SimpleNamespace

    import vbn_bench.localization.peer_map as peer_map
    import vbn_common.exploration as exploration

    camera = make_camera('panoramic', 256, 64)
    frames = [SimpleNamespace(image=None, camera_tilt=None, base_pose=(x, 0.0, 0.0),
                              camera_pose=(x, 0.0, 0.0)) for x in (0.0, 0.5)]
    monkeypatch.setattr(exploration, 'read_exploration', lambda bag: SimpleNamespace(
        frames=frames, camera_info=camera.camera_info(), camera_tilt=None))
    rng = np.random.default_rng(3)
    monkeypatch.setattr(peer_map, 'extract_many', lambda images, sift, workers: [
        _Found(rng.uniform(0, 60, (n_features, 2)).astype(np.float32),
               rng.integers(0, 255, (n_features, 128), dtype=np.uint8)) for _ in images])


class _Found:
    def __init__(self, keypoints: np.ndarray, descriptors: np.ndarray) -> None:
        self.keypoints, self.descriptors = keypoints, descriptors

    def __len__(self) -> int:
        return len(self.keypoints)


def test_a_map_with_too_few_points_is_refused(monkeypatch, tmp_path) -> None:
    # Random descriptors match nothing: no point triangulates. FLANN's index over zero
    # descriptors crashed the process; both the builder and the localizer refuse it.
    from vbn_bench.localization.peer_map import MIN_POINTS, build_peer_map

    _fake_exploration(monkeypatch, 50)
    with pytest.raises(LocalizerError, match='only 0 SIFT tracks triangulate'):
        build_peer_map(tmp_path / 'bag', workers=1)
    assert MIN_POINTS >= 4
    camera = make_camera('panoramic', 256, 64)
    with pytest.raises(LocalizerError, match='no points'):
        PeerLocalizer(_map(np.zeros((0, 3)), camera), camera)


def test_the_cache_key_follows_the_bag_and_the_settings(tmp_path) -> None:
    from vbn_bench.localization.peer_map import PeerMapConfig, source_key

    bag = tmp_path / 'bag'
    bag.mkdir()
    (bag / 'a.mcap').write_bytes(b'1234')
    key = source_key(bag, SiftConfig(), PeerMapConfig())
    assert key == source_key(bag, SiftConfig(), PeerMapConfig())
    assert key != source_key(bag, SiftConfig(), PeerMapConfig(ratio=0.7))
    assert key != source_key(bag, SiftConfig(n_features=100), PeerMapConfig())
    (bag / 'a.mcap').write_bytes(b'12345')             # the bag rebuilt
    assert key != source_key(bag, SiftConfig(), PeerMapConfig())
    saved = tmp_path / 'map.npz'
    camera = make_camera('panoramic', 256, 64)
    peer = _map(np.ones((12, 3)), camera)
    from dataclasses import replace

    from vbn_bench.localization.peer_map import load_peer_map
    replace(peer, source=key).save(saved)
    assert load_peer_map(saved).source == key
