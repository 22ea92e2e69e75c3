"""Message classes by type name, QoS conversions and topic discovery for the bag tools.

There is no ``rosidl_runtime_py`` in the pip-installed ROS 2, so a message class is
found by importing ``<pkg>.msg`` and taking the type from it. QoS offered by
publishers is converted to rosbags' ``Qos`` (what a bag records) and back to an
rclpy ``QoSProfile`` (what ``play`` offers); subscriptions adapt to the offered
QoS the way ``ros2 bag record`` and ``ros2 topic echo`` do.
"""
from __future__ import annotations

import ctypes
import importlib
import logging
import time
from typing import Any

from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from vbn_common.bags import normalize_msgtype
from vbn_common.errors import VbnCommonError

__all__ = [
    'DEFAULT_DEPTH',
    'bag_qos_from_profile',
    'import_message_class',
    'message_type_hash',
    'profile_from_bag_qos',
    'subscription_qos_for',
    'wait_for_topic_type',
]

_LOG = logging.getLogger(__name__)

#: History depth used when a bag records none (DDS discovery does not carry depth).
DEFAULT_DEPTH = 10

_INFINITE = QosTime(0x7FFFFFFF, 0xFFFFFFFF)  # how rosbag2 records an infinite duration


def import_message_class(msgtype: str) -> type | None:
    """Return the Python class of ``pkg/msg/Type``, or None if its package is missing.

    Raises:
        VbnCommonError: The name is not a message type name.
    """
    msgtype = normalize_msgtype(msgtype)
    package, kind, name = msgtype.split('/')
    try:
        module = importlib.import_module(f'{package}.{kind}')
    except ImportError:
        return None
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, 'get_fields_and_field_types'):
        return None
    return cls


class _TypeHash(ctypes.Structure):
    """``rosidl_type_hash_t``: a version byte and a 32-byte SHA-256 digest."""

    _fields_ = [('version', ctypes.c_uint8), ('value', ctypes.c_uint8 * 32)]


class _MessageTypeSupport(ctypes.Structure):
    """The leading fields of Jazzy's ``rosidl_message_type_support_t``."""

    _fields_ = [('typesupport_identifier', ctypes.c_char_p), ('data', ctypes.c_void_p),
                ('func', ctypes.c_void_p), ('get_type_hash_func', ctypes.c_void_p)]


_GET_TYPE_HASH = ctypes.CFUNCTYPE(ctypes.POINTER(_TypeHash), ctypes.c_void_p)


def message_type_hash(cls: type) -> str | None:
    """Return the RIHS01 type hash that a generated message class was built with.

    Jazzy's generated Python classes do not expose the hash; their C type support
    (the one rmw advertises in discovery) does, through its ``get_type_hash_func``.
    The same hash is in ``share/<pkg>/msg/<Type>.json`` of the package's install,
    and rosbags computes it from the definitions (``Typestore.hash_rihs01``).

    Args:
        cls: a generated message class, e.g. ``geometry_msgs.msg.PoseStamped``.

    Returns:
        ``'RIHS01_<64 hex digits>'``, or None when ``cls`` is not a generated message
        class or its type support cannot be loaded or carries no hash.
    """
    metaclass = type(cls)
    import_type_support = getattr(metaclass, '__import_type_support__', None)
    if import_type_support is None:
        return None
    if getattr(metaclass, '_TYPE_SUPPORT', None) is None:
        import_type_support()  # logs at DEBUG and leaves None if the library is missing
    capsule = getattr(metaclass, '_TYPE_SUPPORT', None)
    if capsule is None:
        return None
    get_name = ctypes.pythonapi.PyCapsule_GetName
    get_name.restype, get_name.argtypes = ctypes.c_char_p, [ctypes.py_object]
    get_pointer = ctypes.pythonapi.PyCapsule_GetPointer
    get_pointer.restype = ctypes.c_void_p
    get_pointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    address = get_pointer(capsule, get_name(capsule))
    if not address:
        return None
    support = _MessageTypeSupport.from_address(address)
    # Only the C type support's layout is known here (rosidl_generator_py uses it).
    if support.typesupport_identifier != b'rosidl_typesupport_c' or not support.get_type_hash_func:
        return None
    type_hash = _GET_TYPE_HASH(support.get_type_hash_func)(address)
    if not type_hash or type_hash.contents.version != 1:
        return None
    return 'RIHS01_' + bytes(type_hash.contents.value).hex()


def profile_from_bag_qos(profiles: list[Qos]) -> QoSProfile:
    """Return the QoS ``play`` offers for a topic, from the profiles recorded in the bag.

    Reliability and durability follow the recorded offer (reliable only if every
    recorded publisher was reliable, transient-local only if every one was);
    history is keep-last with the recorded depth, or :data:`DEFAULT_DEPTH` when
    none was recorded. Nothing recorded: reliable, volatile, depth 10.
    """
    if not profiles:
        return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEFAULT_DEPTH,
                          reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.VOLATILE)
    reliable = all(p.reliability == QosReliability.RELIABLE for p in profiles)
    transient = all(p.durability == QosDurability.TRANSIENT_LOCAL for p in profiles)
    depths = [p.depth for p in profiles if p.history in (QosHistory.KEEP_LAST,
                                                         QosHistory.KEEP_ALL) and p.depth > 0]
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST,
        depth=max(depths) if depths else DEFAULT_DEPTH,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE)


def _bag_time(duration: Any) -> QosTime:
    nanoseconds = int(getattr(duration, 'nanoseconds', 0))
    if nanoseconds <= 0 or nanoseconds >= 0x7FFFFFFF * 10**9:
        return _INFINITE if nanoseconds != 0 else QosTime(0, 0)
    return QosTime(nanoseconds // 10**9, nanoseconds % 10**9)


#: Recorded for an offer whose history DDS discovery does not tell (rclpy's default).
RECORDED_DEPTH = 10


def bag_qos_from_profile(profile: QoSProfile) -> Qos:
    """Convert a publisher's offered rclpy QoS to the rosbags ``Qos`` a bag records.

    DDS discovery carries reliability, durability, deadline, lifespan and liveliness but
    not the history: a remote publisher's offer reads ``history UNKNOWN, depth 0``. A bag
    with that replays with a depth of 0 (nothing kept), so such an offer is recorded
    as ``keep_last`` with :data:`RECORDED_DEPTH`, the depth rclpy and rosbag2 default to.
    """
    def enum(target: Any, value: Any) -> Any:
        try:
            return target(int(value))
        except ValueError:
            return target.UNKNOWN
    history, depth = enum(QosHistory, profile.history), int(profile.depth)
    if history in (QosHistory.UNKNOWN, QosHistory.SYSTEM_DEFAULT) or (
            history == QosHistory.KEEP_LAST and depth <= 0):
        history, depth = QosHistory.KEEP_LAST, RECORDED_DEPTH
    return Qos(
        history, depth,
        enum(QosReliability, profile.reliability), enum(QosDurability, profile.durability),
        _bag_time(profile.deadline), _bag_time(profile.lifespan),
        enum(QosLiveliness, profile.liveliness), _bag_time(profile.liveliness_lease_duration),
        bool(profile.avoid_ros_namespace_conventions))


def subscription_qos_for(offered: list[QoSProfile], depth: int = 100) -> QoSProfile:
    """Return a subscription QoS compatible with every offered profile (like ros2 bag record).

    Reliable when every publisher is reliable, else best effort; transient-local
    when every publisher is, else volatile (so latched data is received).
    """
    reliable = bool(offered) and all(
        p.reliability == ReliabilityPolicy.RELIABLE for p in offered)
    transient = bool(offered) and all(
        p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in offered)
    return QoSProfile(
        history=HistoryPolicy.KEEP_LAST, depth=depth,
        reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if transient else DurabilityPolicy.VOLATILE,
        liveliness=LivelinessPolicy.SYSTEM_DEFAULT)


def topic_types(node: Node) -> dict[str, list[str]]:
    """``{topic: [types]}`` as the graph knows it now."""
    return {name: list(types) for name, types in node.get_topic_names_and_types()}


def wait_for_topic_type(node: Node, topic: str, executor: Any, timeout_s: float | None) -> str:
    """Spin until ``topic`` has a publisher in the graph; return its type.

    Raises:
        VbnCommonError: Not seen within ``timeout_s`` seconds, or several types.
    """
    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    while True:
        types = topic_types(node).get(topic)
        if types and node.count_publishers(topic) > 0:
            if len(types) > 1:
                raise VbnCommonError(
                    f'topic {topic} has several types ({", ".join(types)})')
            return types[0]
        if deadline is not None and time.monotonic() > deadline:
            raise VbnCommonError(
                f'no publisher of {topic} appeared within {timeout_s:g} s')
        executor.spin_once(timeout_sec=0.05)
