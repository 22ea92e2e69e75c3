"""A synthetic world for the localizer's unit tests: wall points seen by panoramas.

Scene points lie on the walls of a 6 m x 3 m room at heights around the camera's; the
camera is the project's cylindrical panorama (1024 x 256). Two regions overlap in the
middle of the room; each has three model views whose keypoints are the exact
projections of the points it sees. The database is built with the real
``landmark_db.database`` dataclasses, so the localizer's index reads it as it reads a
built one.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from landmark_db.database import (
    BuildInfo,
    CameraIntrinsics,
    FeatureClasses,
    LandmarkDatabase,
    ModelView,
    RegionRecord,
    SampledPoses,
)
from landmark_db.database.build_info import utc_now_iso
from vbn_common.geometry.camera import make_camera
from vbn_common.geometry.frames import world_points_to_camera

CAMERA = make_camera('panoramic')
HEIGHT = 1.2  # camera height; points are stored relative to the floor


def wall_points(rng: np.random.Generator, n: int = 60) -> np.ndarray:
    """(n, 3) points on the walls of [0, 6] x [0, 3], z in [0.4, 2.2] m."""
    side = rng.integers(0, 4, n)
    t = rng.uniform(0, 1, n)
    x = np.select([side == 0, side == 1, side == 2], [6 * t, 6.0, 6 * t], 0.0)
    y = np.select([side == 0, side == 1, side == 2], [0.0, 3 * t, 3.0], 3 * t)
    return np.stack([x, y, rng.uniform(0.4, 2.2, n)], axis=1)


#: The camera of :func:`wall_ahead`, 4 m before the wall x = 6, facing it.
AHEAD = np.array([2.0, 1.5, 0.05])


def wall_ahead(n: int, low: float, high: float):  # noqa: ANN201 - (points, index, uv, ids)
    """Points on the wall x = 6 between y = ``low`` and ``high`` (z 0.6 to 2.0 m).

    Returns ``(points, DatabaseIndex, uv, ids)``: the pixels at which :data:`AHEAD`
    sees them, without noise, and the points it sees (seeded: the same every call).
    """
    from landmark_localizer.index import DatabaseIndex

    rng = np.random.default_rng(11)
    points = np.column_stack([np.full(n, 6.0), rng.uniform(low, high, n),
                              rng.uniform(0.6, 2.0, n)])
    index = DatabaseIndex(synthetic_database(rng, points))
    uv, ok = project(AHEAD, points)
    ids = np.flatnonzero(ok)
    return points, index, uv[ids], ids


def project(pose: np.ndarray, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels of points seen by the camera at planar pose (x, y, yaw)."""
    optical = world_points_to_camera(np.asarray(pose, float), HEIGHT, points)
    return CAMERA.project(optical)


def grid_poses() -> np.ndarray:
    xs, ys = np.meshgrid(np.arange(0.5, 5.6, 0.5), np.arange(0.5, 2.6, 0.5))
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


def synthetic_database(rng: np.random.Generator, points: np.ndarray) -> LandmarkDatabase:
    """Two overlapping regions (x <= 3.5 and x >= 2.5), three model views each."""
    xy = grid_poses()
    n = len(xy)
    ix = np.round((xy[:, 0] - 0.5) / 0.5).astype(int)
    iy = np.round((xy[:, 1] - 0.5) / 0.5).astype(int)
    edges = [(i, j) for i in range(n) for j in range(i + 1, n)
             if abs(ix[i] - ix[j]) + abs(iy[i] - iy[j]) == 1]
    n_classes = len(points)
    descriptors = rng.integers(0, 256, (n_classes, 128)).astype(np.uint8)
    visibility = sp.csr_matrix(np.ones((n, n_classes), bool))
    regions = []
    for poses, views in (
            (np.flatnonzero(xy[:, 0] <= 3.5), [(0.5, 0.5, 0.3), (3.5, 2.5, -0.4),
                                               (0.5, 2.5, 1.0)]),
            (np.flatnonzero(xy[:, 0] >= 2.5), [(2.5, 0.5, 0.0), (5.5, 2.5, 2.0),
                                               (5.5, 0.5, -1.0)])):
        model_views = []
        for k, pose in enumerate(views):
            uv, ok = project(np.array(pose), points)
            ids = np.flatnonzero(ok)
            model_views.append(ModelView(
                pose=int(poses[0]), image_stamp_ns=k, image_index=k, x=pose[0], y=pose[1],
                yaw=pose[2], class_ids=ids, keypoints=uv[ids].astype(np.float32),
                descriptors=descriptors[ids]))
        shown = set.intersection(*(set(v.class_ids.tolist()) for v in model_views))
        landmark = np.array(sorted(shown)[:8])
        extra = np.array(sorted(shown)[8:40])
        regions.append(RegionRecord(poses=poses, landmark=landmark, extra=extra,
                                    model_views=tuple(model_views)))
    info = BuildInfo(k=8, rho=0, sigma=0, algorithm='B2', pose_source='ground_truth',
                     source_bag='synthetic', created_utc=utc_now_iso(),
                     camera=CameraIntrinsics(kind='panoramic', width=CAMERA.width,
                                             height=CAMERA.height, K=_k(), D=np.zeros(0),
                                             distortion_model='cylindrical',
                                             frame_id='camera'),
                     frames={'map': 'map', 'base': 'base_link', 'camera': 'camera'},
                     sift={}, parameters={'camera_mount': [0.0, 0.0, 0.0]})
    return LandmarkDatabase(
        info=info, poses=SampledPoses(xy=xy, yaw=np.zeros(n), grid=np.stack([ix, iy], 1),
                                      edges=np.array(edges), spacing=0.5),
        classes=FeatureClasses(descriptors, np.arange(n_classes + 1), visibility),
        regions=tuple(regions), uncovered=np.zeros(0, np.int64))


def _k() -> np.ndarray:
    info = CAMERA.camera_info()
    return np.asarray(info.k, float).reshape(3, 3)
