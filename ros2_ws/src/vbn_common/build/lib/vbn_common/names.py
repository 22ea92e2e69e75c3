"""The contract topic and frame names, once (``DESIGN.md``, "Topics and frames").

Every module that reads, writes, publishes or subscribes one of these names takes it
from here. The topic names are those at the root namespace; a node creates its
endpoints with :func:`relative`, so that ``-r __ns:=/robot1`` (or a remap) moves them
as ROS 2 resolves names: ``relative(LOCALIZER_POSE)`` is ``localizer/pose``, which is
``/localizer/pose`` at the root and ``/robot1/localizer/pose`` in ``/robot1``. Bags
store the root names. Frames follow REP 105, plus the camera's optical frame (REP 103:
``z`` forward, ``x`` right, ``y`` down) of the image headers.
"""
from __future__ import annotations

__all__ = [
    'BASE_FRAME',
    'BUILDER_PROGRESS',
    'BUILDER_REGIONS',
    'CAMERA_FRAME',
    'CAMERA_INFO',
    'DIAGNOSTICS',
    'ESTIMATED_POSE',
    'GROUND_TRUTH_POSE',
    'IMAGE_COMPRESSED',
    'IMAGE_RAW',
    'IMAGE_TOPICS',
    'INITIAL_POSE',
    'LOCALIZER_POSE',
    'LOCALIZER_POSE_WITH_COVARIANCE',
    'LOCALIZER_REGION',
    'LOCALIZER_REGIONS',
    'MAP_FRAME',
    'ODOM',
    'ODOM_FRAME',
    'TF',
    'TF_STATIC',
    'relative',
]

#: Raw camera images (``sensor_msgs/Image``).
IMAGE_RAW = '/camera/image_raw'
#: Compressed camera images (``sensor_msgs/CompressedImage``).
IMAGE_COMPRESSED = '/camera/image_raw/compressed'
#: Both image topics; where a bag has both, the raw (lossless) one is read.
IMAGE_TOPICS = (IMAGE_RAW, IMAGE_COMPRESSED)
#: The camera's calibration (``sensor_msgs/CameraInfo``).
CAMERA_INFO = '/camera/camera_info'
#: Wheel odometry (``nav_msgs/Odometry``, frame ``odom``).
ODOM = '/odom'
#: The true pose of ``base_link`` in ``map`` (``geometry_msgs/PoseStamped``, rendered bags).
GROUND_TRUTH_POSE = '/ground_truth/pose'
#: Image poses estimated from the images and the odometry (``geometry_msgs/PoseStamped``).
ESTIMATED_POSE = '/estimated/pose'
#: The localizer's pose of ``base_link`` in ``map`` (``geometry_msgs/PoseStamped``).
LOCALIZER_POSE = '/localizer/pose'
#: The same with its covariance (``geometry_msgs/PoseWithCovarianceStamped``).
LOCALIZER_POSE_WITH_COVARIANCE = '/localizer/pose_with_covariance'
#: The region tracked (``std_msgs/Int32``, -1 when lost).
LOCALIZER_REGION = '/localizer/region'
#: The database's regions for RViz (``visualization_msgs/MarkerArray``, latched).
LOCALIZER_REGIONS = '/localizer/regions'
#: The builder's progress (``diagnostic_msgs/DiagnosticArray``).
BUILDER_PROGRESS = '/builder/progress'
#: The built regions for RViz (``visualization_msgs/MarkerArray``, latched).
BUILDER_REGIONS = '/builder/regions'
#: Node diagnostics (``diagnostic_msgs/DiagnosticArray``).
DIAGNOSTICS = '/diagnostics'
#: A pose hint, as RViz's "2D Pose Estimate" and nav2 send it.
INITIAL_POSE = '/initialpose'
#: Transforms (``tf2_msgs/TFMessage``).
TF = '/tf'
#: Static transforms (``tf2_msgs/TFMessage``, transient-local).
TF_STATIC = '/tf_static'

#: REP 105 world-fixed frame (the localizer's and the ground truth's frame).
MAP_FRAME = 'map'
#: REP 105 odometry frame (continuous, drifting).
ODOM_FRAME = 'odom'
#: REP 105 robot body frame (REP 103 axes: x forward, y left, z up).
BASE_FRAME = 'base_link'
#: The camera's optical frame (z forward, x right, y down), the image headers' frame.
CAMERA_FRAME = 'camera'


def relative(topic: str) -> str:
    """Return a root topic name as a name relative to the node's namespace.

    Args:
        topic: A name from this module (``/localizer/pose``).

    Returns:
        The name without its leading slash (``localizer/pose``).
    """
    return topic.lstrip('/')
