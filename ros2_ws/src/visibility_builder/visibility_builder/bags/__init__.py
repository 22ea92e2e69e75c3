"""Read and write rosbag2 MCAP bags (no rclpy): the public API of the bag modules.

Import bag reading, writing, QoS, serialization and summaries from here
(``from visibility_builder.bags import open_bag, BagWriter``).
"""
from __future__ import annotations

from visibility_builder.bag_info import (
    BagSummary,
    TopicSummary,
    bag_paths,
    format_bag_info,
    format_size,
    summarize_bag,
)
from visibility_builder.bag_io import (
    ROSBAG2_VERSION,
    TYPESTORE,
    BagReader,
    BagWriter,
    TopicInfo,
    default_qos,
    deserialize,
    dump_qos_yaml,
    normalize_msgtype,
    open_bag,
    parse_qos_profiles,
    serialize,
)

__all__ = [
    'ROSBAG2_VERSION',
    'TYPESTORE',
    'BagReader',
    'BagSummary',
    'BagWriter',
    'TopicInfo',
    'TopicSummary',
    'bag_paths',
    'default_qos',
    'deserialize',
    'dump_qos_yaml',
    'format_bag_info',
    'format_size',
    'normalize_msgtype',
    'open_bag',
    'parse_qos_profiles',
    'serialize',
    'summarize_bag',
]
