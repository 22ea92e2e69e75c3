"""Read and write rosbag2 MCAP bags (no rclpy), one module per concern.

* :mod:`.writer`: :class:`BagWriter`, zstd-chunked rosbag2 directories written atomically;
* :mod:`.reader`: :class:`BagReader` / :func:`open_bag`, bag directories or bare ``.mcap``
  files, damaged ones included;
* :mod:`.recovery`: the scan that reads the intact part of a damaged MCAP file;
* :mod:`.qos`: offered QoS profiles as rosbag2 records them;
* :mod:`.serialization`: CDR with the ROS 2 Jazzy typestore;
* :mod:`.info`: the summary ``vbn bag-info`` prints.

Import from here: ``from vbn_common.bags import open_bag, BagWriter``.
"""
from __future__ import annotations

from vbn_common.bags.info import (
    BagSummary,
    TopicSummary,
    bag_paths,
    format_bag_info,
    format_size,
    summarize_bag,
)
from vbn_common.bags.qos import default_qos, dump_qos_yaml, parse_qos_profiles
from vbn_common.bags.reader import BagReader, TopicInfo, open_bag
from vbn_common.bags.serialization import (
    TYPESTORE,
    deserialize,
    normalize_msgtype,
    serialize,
)
from vbn_common.bags.writer import ROSBAG2_VERSION, BagWriter

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
