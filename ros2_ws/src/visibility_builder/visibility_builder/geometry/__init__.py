"""Shared geometry: camera models and frames (thesis Section 7.5; REP 103 and REP 105).

Core modules (no rclpy, no message types) used by the renderer, the builder, image
pose estimation and the localizer: :mod:`.camera` (the panoramic and pinhole camera
models, their ``CameraInfo`` convention, pixel <-> ray and bearing conversions) and
:mod:`.frames` (frame names, planar poses, yaw <-> quaternion, the optical frame).
The 2-D segment helpers of the scene live one package lower, in
:mod:`landmark_db.geometry2d`.
"""
from __future__ import annotations

from visibility_builder.geometry.camera import (
    CameraInfoFields,
    CameraInfoLike,
    CameraModel,
    PanoramicCamera,
    PinholeCamera,
    camera_from_info,
    make_camera,
)
from visibility_builder.geometry.frames import (
    BASE_FRAME,
    BASE_TO_CAMERA_QUATERNION,
    BASE_TO_CAMERA_ROTATION,
    CAMERA_FRAME,
    MAP_FRAME,
    ODOM_FRAME,
    camera_points_to_world,
    compose_poses,
    invert_pose,
    quaternion_yaw,
    transform_points,
    world_points_to_camera,
    wrap_angle,
    yaw_quaternion,
)

__all__ = [
    'BASE_FRAME',
    'BASE_TO_CAMERA_QUATERNION',
    'BASE_TO_CAMERA_ROTATION',
    'CAMERA_FRAME',
    'MAP_FRAME',
    'ODOM_FRAME',
    'CameraInfoFields',
    'CameraInfoLike',
    'CameraModel',
    'PanoramicCamera',
    'PinholeCamera',
    'camera_from_info',
    'camera_points_to_world',
    'compose_poses',
    'invert_pose',
    'make_camera',
    'quaternion_yaw',
    'transform_points',
    'world_points_to_camera',
    'wrap_angle',
    'yaw_quaternion',
]
