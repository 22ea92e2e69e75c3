"""Broadcast transforms on ``/tf`` or ``/tf_static`` from an rclpy node (the glue half).

The core computes :class:`~vbn_common.geometry.transforms.StampedTransform` values; this
module turns them into ``tf2_msgs/TFMessage`` and publishes them with the QoS that tf2's
own broadcasters use, so that any tf2 listener (RViz, nav2) receives them:

- ``/tf``: reliable, volatile, keep-last 100 (``tf2_ros.DynamicBroadcasterQoS``);
- ``/tf_static``: reliable, transient-local, keep-last 1 (``tf2_ros.StaticBroadcasterQoS``),
  so that a listener that starts later still gets every static transform. As tf2_ros does,
  the static broadcaster keeps every child frame it was given and republishes them all in
  one message, so a later call never hides an earlier frame.

``tf2_msgs`` comes from the workspace (``ros2_ws/src/tf2_msgs``) here, or from the system
on a full ROS 2 install.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from vbn_common.geometry.transforms import StampedTransform
from vbn_common.names import TF, TF_STATIC

__all__ = ['DYNAMIC_QOS', 'STATIC_QOS', 'TransformBroadcaster', 'to_message']

#: QoS of tf2_ros.TransformBroadcaster on /tf.
DYNAMIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
#: QoS of tf2_ros.StaticTransformBroadcaster on /tf_static.
STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


def to_message(transform: StampedTransform) -> Any:
    """Return the ``geometry_msgs/TransformStamped`` of a core transform."""
    from geometry_msgs.msg import TransformStamped

    msg = TransformStamped()
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(transform.stamp_ns, 10**9)
    msg.header.frame_id = transform.parent
    msg.child_frame_id = transform.child
    t, q = transform.translation, transform.rotation
    msg.transform.translation.x, msg.transform.translation.y = float(t[0]), float(t[1])
    msg.transform.translation.z = float(t[2])
    (msg.transform.rotation.x, msg.transform.rotation.y, msg.transform.rotation.z,
     msg.transform.rotation.w) = (float(v) for v in q)
    return msg


class TransformBroadcaster:
    """Publishes transforms on ``/tf`` (or ``/tf_static`` with ``static=True``).

    Args:
        node: The node that owns the publisher.
        static: Latch on ``/tf_static`` instead of streaming on ``/tf``.
        topic: The topic (default ``/tf`` or ``/tf_static``, as tf2_ros; a node whose
            names follow its namespace passes ``tf``, which resolves to ``/tf`` at the
            root namespace).
    """

    def __init__(self, node: Node, static: bool = False, topic: str | None = None) -> None:
        from tf2_msgs.msg import TFMessage

        self._message_class = TFMessage
        self.static = static
        self.node = node
        self.publisher = node.create_publisher(
            TFMessage, topic or (TF_STATIC if static else TF),
            STATIC_QOS if static else DYNAMIC_QOS)
        self._static_frames: dict[str, Any] = {}

    def destroy(self) -> None:
        """Destroy the publisher (the broadcaster cannot send afterwards)."""
        self.node.destroy_publisher(self.publisher)

    def send(self, transforms: StampedTransform | Iterable[StampedTransform]) -> None:
        """Publish one transform or several in one ``TFMessage``."""
        if isinstance(transforms, StampedTransform):
            transforms = [transforms]
        messages = [to_message(t) for t in transforms]
        if self.static:
            for msg in messages:
                self._static_frames[msg.child_frame_id] = msg
            messages = list(self._static_frames.values())
        self.publisher.publish(self._message_class(transforms=messages))
