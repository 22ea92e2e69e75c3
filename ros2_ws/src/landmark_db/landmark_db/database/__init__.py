"""The landmark database: one SQLite file per built world.

:mod:`.model` holds the in-memory database (frozen, validated dataclasses; the build's
camera and settings in :mod:`.build_info`, the field checks in :mod:`.fields`),
:mod:`.schema` the SQLite schema and its version, :mod:`.store` the atomic writer and
the read-only reader. Typical use::

    from landmark_db.database import open_database, write_database

    write_database('room.db', database)      # builder: atomic, one transaction
    database = open_database('room.db')      # localizer: read-only, checked
"""
from __future__ import annotations

from landmark_db.database.build_info import (
    CAMERA_KINDS,
    POSE_SOURCES,
    BuildInfo,
    CameraIntrinsics,
    utc_now_iso,
)
from landmark_db.database.fields import DESCRIPTOR_SIZE
from landmark_db.database.model import (
    FeatureClasses,
    LandmarkDatabase,
    ModelView,
    RegionAdjacency,
    RegionRecord,
    SampledPoses,
)
from landmark_db.database.points import ScenePoints
from landmark_db.database.schema import APPLICATION_ID, SCHEMA_VERSION
from landmark_db.database.store import (
    DatabaseSummary,
    database_image,
    database_summary,
    open_database,
    write_database,
)

__all__ = [
    'APPLICATION_ID',
    'CAMERA_KINDS',
    'DESCRIPTOR_SIZE',
    'POSE_SOURCES',
    'SCHEMA_VERSION',
    'BuildInfo',
    'CameraIntrinsics',
    'DatabaseSummary',
    'FeatureClasses',
    'LandmarkDatabase',
    'ModelView',
    'RegionAdjacency',
    'RegionRecord',
    'SampledPoses',
    'ScenePoints',
    'database_image',
    'database_summary',
    'open_database',
    'utc_now_iso',
    'write_database',
]
