"""Hand-built landmark databases for the database tests (importable by subprocesses too).

A grid world with random visibility is decomposed by the core's ``decompose`` so that
its regions are valid; descriptors, keypoints and model views are fabricated with an
explicit ``rng``.
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
import sqlite3

import numpy as np

from landmark_db.database import (
    BuildInfo,
    CameraIntrinsics,
    FeatureClasses,
    LandmarkDatabase,
    ModelView,
    RegionRecord,
    SampledPoses,
    ScenePoints,
)
from landmark_db.decomposition import decompose
from landmark_db.world import grid_world


def sample_camera() -> CameraIntrinsics:
    K = np.array([[320.0, 0.0, 320.5], [0.0, 320.0, 240.25], [0.0, 0.0, 1.0]])
    return CameraIntrinsics('pinhole', 640, 480, K, np.array([0.01, -0.002, 0.0, 0.0, 0.0]),
                            'plumb_bob', 'camera')


def sample_database(rng: np.random.Generator, nx: int = 3, ny: int = 3, n_classes: int = 12,
                    k: int = 2, rho: int = 0, algorithm: str = 'B2', density: float = 0.9,
                    view_noise_features: int = 3) -> LandmarkDatabase:
    """A database on an ``nx`` x ``ny`` grid (0.5 m) whose regions come from ``decompose``."""
    n = nx * ny
    # Each class is seen from a random rectangle of cells, each cell of which it may miss.
    x0, x1 = np.sort(rng.integers(0, nx + 1, (2, n_classes)), axis=0)
    y0, y1 = np.sort(rng.integers(0, ny + 1, (2, n_classes)), axis=0)
    iy, ix = np.divmod(np.arange(n), nx)
    inside = ((ix[:, None] >= x0) & (ix[:, None] <= x1)
              & (iy[:, None] >= y0) & (iy[:, None] <= y1))
    visible = inside & (rng.random((n, n_classes)) < density)
    world = grid_world(nx, ny, 0.5, visible)
    decomposition = decompose(world, algorithm, k, rho, rng=0)
    poses = SampledPoses(world.poses, rng.uniform(-np.pi, np.pi, n),
                         np.column_stack([ix, iy]), world.edges, 0.5)
    counts = rng.integers(1, 4, n_classes)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    classes = FeatureClasses(rng.integers(0, 256, (int(offsets[-1]), 128), dtype=np.uint8),
                             offsets, world.visible)
    regions = []
    for region in decomposition.regions:
        seen = np.flatnonzero(np.asarray(world.visible[region.poses].sum(axis=0)).ravel())
        extra = rng.permutation(np.setdiff1d(seen, region.features))[:3]
        ends = [int(region.poses[0]), int(region.poses[-1])]
        views = []
        for pose in dict.fromkeys(ends):
            own = world.features_of(pose)
            ids = np.concatenate([rng.permutation(own),
                                  np.full(view_noise_features, -1)]).astype(np.int64)
            m = ids.size
            views.append(ModelView(pose, 1_700_000_000_000_000_000 + pose * 10**8, 3 * pose,
                                   float(world.poses[pose, 0]) + 0.05,
                                   float(world.poses[pose, 1]), float(rng.uniform(-3, 3)),
                                   ids, (rng.random((m, 2)) * [640, 480]).astype(np.float32),
                                   rng.integers(0, 256, (m, 128), dtype=np.uint8)))
        regions.append(RegionRecord(region.poses, rng.permutation(region.features), extra,
                                    tuple(views)))
    info = BuildInfo(k, rho, 0, algorithm, 'ground_truth', 'bags/room_exploration',
                     '2026-12-01T13:00:00+00:00', sample_camera(),
                     {'map': 'map', 'base_link': 'base_link', 'camera': 'camera'},
                     {'n_features': 0, 'contrast_threshold': 0.04, 'ratio': 0.8},
                     {'gamma': 5, 'tau': 250.0, 'filters': ['min_poses', 'components'],
                      'seed': 0},
                     decomposition_seconds=decomposition.seconds)
    # Scene points: half of the classes, and as many of no class.
    named = rng.permutation(n_classes)[:n_classes // 2]
    ids = np.concatenate([named, np.full(named.size, -1)]).astype(np.int64)
    points = ScenePoints(rng.uniform(-1, 4, (ids.size, 3)), ids,
                         rng.integers(0, 256, (ids.size, 128), dtype=np.uint8),
                         rng.integers(2, 30, ids.size),
                         np.column_stack([rng.uniform(0, 3, (ids.size, 2)),
                                          rng.uniform(0, 1, ids.size)]))
    # Their exploration patches (schema 4), the last point without one.
    patches = rng.integers(0, 256, (ids.size, 7, 7), dtype=np.uint8)
    axes = rng.uniform(-0.01, 0.01, (ids.size, 2, 3)).astype(np.float32)
    patches[-1], axes[-1] = 0, np.nan
    points = replace(points, patches=patches, patch_axes=axes)
    return LandmarkDatabase(info, poses, classes, tuple(regions), decomposition.uncovered,
                            points)


def large_database(rng: np.random.Generator, view_features: int = 4000) -> LandmarkDatabase:
    """A database of some tens of MB (many model-view features), for the crash tests."""
    small = sample_database(rng, nx=8, ny=8, n_classes=60, k=3)
    regions = []
    for region in small.regions:
        views = []
        for view in region.model_views:
            extra = view_features - len(view)
            ids = np.concatenate([view.class_ids, np.full(extra, -1)])
            views.append(ModelView(view.pose, view.image_stamp_ns, view.image_index, view.x,
                                   view.y, view.yaw, ids,
                                   rng.random((ids.size, 2)).astype(np.float32) * 640,
                                   rng.integers(0, 256, (ids.size, 128), dtype=np.uint8)))
        regions.append(RegionRecord(region.poses, region.landmark, region.extra,
                                    tuple(views * 20)))
    return LandmarkDatabase(small.info, small.poses, small.classes, tuple(regions),
                            small.uncovered)


def edited_copy(source: Path, target: Path, *statements: str) -> Path:
    """Copy a database file and run SQL statements on the copy (damage on purpose)."""
    target.write_bytes(source.read_bytes())
    connection = sqlite3.connect(target)
    for statement in statements:
        connection.execute(statement)
    connection.commit()
    connection.close()
    return target
