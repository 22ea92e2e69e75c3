"""Tests of the full-feature-database baseline: its size and its cache file."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from landmark_localizer.localizer import LOST, Frame
from vbn_bench.localization.baseline import (
    FullDatabaseLocalizer,
    FullFeatureDatabase,
    load_full_database,
)
from vbn_common.features import SiftConfig

PANORAMA = (1024, 256, 'cylindrical', np.zeros(0),
            np.array([1024 / (2 * np.pi), 0, 512, 0, 1024 / (2 * np.pi), 128, 0, 0, 1.0]))


def small_database(rng: np.random.Generator) -> FullFeatureDatabase:
    n = 50
    return FullFeatureDatabase(
        view_poses=np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.1]]),
        keypoints=rng.uniform(0, 256, (n, 2)).astype(np.float32),
        descriptors=rng.integers(0, 256, (n, 128), dtype=np.uint8),
        view_of=np.repeat(np.arange(2, dtype=np.int32), n // 2),
        camera_info=PANORAMA, camera_mount=np.array([0.1, 0.0, 0.0]),
        sift=SiftConfig(contrast_threshold=0.03))


def test_size_is_descriptors_and_keypoints() -> None:
    database = small_database(np.random.default_rng(0))
    assert database.nbytes == 50 * 128 + 50 * 2 * 4


def test_cache_round_trip(tmp_path: Path) -> None:
    database = small_database(np.random.default_rng(1))
    database.save(tmp_path / 'full.npz')
    again = load_full_database(tmp_path / 'full.npz')
    np.testing.assert_array_equal(again.descriptors, database.descriptors)
    np.testing.assert_array_equal(again.view_of, database.view_of)
    np.testing.assert_allclose(again.keypoints, database.keypoints)
    assert again.sift == database.sift
    assert again.camera() == database.camera()
    np.testing.assert_allclose(again.camera_mount, database.camera_mount)


def test_featureless_frame_gives_no_pose() -> None:
    localizer = FullDatabaseLocalizer(small_database(np.random.default_rng(2)))
    estimate = localizer.step(Frame(1, np.full((256, 1024), 128, np.uint8)))
    assert estimate.state == LOST and estimate.pose is None and estimate.region == -1
