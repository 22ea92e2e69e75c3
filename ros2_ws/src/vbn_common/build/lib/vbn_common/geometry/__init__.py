"""Shared geometry: camera models, frames, pose solvers (thesis 7.2-7.5; REP 103, REP 105).

Core modules (no rclpy, no message types) used by the renderer, the builder, image
pose estimation and the localizer: :mod:`.camera` (the panoramic and pinhole camera
models, their ``CameraInfo`` convention, pixel <-> ray and bearing conversions),
:mod:`.frames` (frame names, planar poses, yaw <-> quaternion, the optical frame),
:mod:`.transforms` (stamped 3-D transforms, the ``map -> odom`` correction), the
two-view solvers of Chapter 7, one method per module (:mod:`.panoramic_planar` 7.5.2,
:mod:`.pinhole_planar` 7.5.1, :mod:`.essential` 7.4, :mod:`.linear_combination` 7.3)
over :mod:`.epipolar` and one MSAC loop (:mod:`.ransac`), their result
(:mod:`.motion`), the dispatcher by camera kind (:mod:`.two_view`) and
:mod:`.localize` (the current pose from two or more model views of known pose).
The 2-D segment helpers of the scene live one package lower, in
:mod:`landmark_db.geometry2d`.
"""
from __future__ import annotations

from vbn_common.geometry.camera import (
    CameraInfoFields,
    CameraInfoLike,
    CameraModel,
    PanoramicCamera,
    PinholeCamera,
    camera_from_info,
    make_camera,
)
from vbn_common.geometry.essential import general_essential
from vbn_common.geometry.frames import (
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
from vbn_common.geometry.linear_combination import linear_combination_of_views
from vbn_common.geometry.localize import (
    PoseEstimate,
    position_from_two_views,
    position_from_views,
)
from vbn_common.geometry.motion import RelativeMotion, TwoViewConfig
from vbn_common.geometry.panoramic_planar import panoramic_planar_motion
from vbn_common.geometry.pinhole_planar import pinhole_planar_essential
from vbn_common.geometry.two_view import relative_motion

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
    'PoseEstimate',
    'RelativeMotion',
    'TwoViewConfig',
    'camera_from_info',
    'camera_points_to_world',
    'compose_poses',
    'general_essential',
    'invert_pose',
    'linear_combination_of_views',
    'make_camera',
    'panoramic_planar_motion',
    'pinhole_planar_essential',
    'position_from_two_views',
    'position_from_views',
    'quaternion_yaw',
    'relative_motion',
    'transform_points',
    'world_points_to_camera',
    'wrap_angle',
    'yaw_quaternion',
]
