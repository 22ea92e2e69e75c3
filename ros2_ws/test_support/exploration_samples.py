"""Small exploration bags written message by message, for tests of the builder's input.

``exploration_messages`` lists ``(topic, msgtype, stamp, message)`` of a tiny 8 x 6 mono8
exploration (images, camera info, ground truth, /tf, /tf_static as asked) that
``write_bag`` writes with the project's BagWriter; tests break one piece at a time.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vbn_common.bags import TYPESTORE, BagWriter

T = TYPESTORE.types
IMAGE = 'sensor_msgs/msg/Image'
INFO = 'sensor_msgs/msg/CameraInfo'
POSE = 'geometry_msgs/msg/PoseStamped'
TF = 'tf2_msgs/msg/TFMessage'
T0 = 1_735_689_600 * 10**9
W, H = 8, 6


# -- message builders -------------------------------------------------------------------
def header(stamp: int, frame: str) -> object:
    return T['std_msgs/msg/Header'](
        stamp=T['builtin_interfaces/msg/Time'](sec=stamp // 10**9, nanosec=stamp % 10**9),
        frame_id=frame)


def image(stamp: int, encoding: str = 'mono8', step: int | None = None,
          size: int | None = None, value: int = 7) -> object:
    bpp = {'mono8': 1, 'bgr8': 3, 'yuv422': 2}[encoding]
    step = W * bpp if step is None else step
    size = step * H if size is None else size
    return T[IMAGE](header=header(stamp, 'camera'), height=H, width=W, encoding=encoding,
                    is_bigendian=0, step=step, data=np.full(size, value, np.uint8))


def info(stamp: int, fx: float = 4.0) -> object:
    roi = T['sensor_msgs/msg/RegionOfInterest'](x_offset=0, y_offset=0, height=0, width=0,
                                                do_rectify=False)
    k = np.array([fx, 0, (W - 1) / 2, 0, fx, (H - 1) / 2, 0, 0, 1], dtype=np.float64)
    return T[INFO](header=header(stamp, 'camera'), height=H, width=W,
                   distortion_model='plumb_bob', d=np.zeros(5), k=k, r=np.eye(3).reshape(-1),
                   p=np.zeros(12), binning_x=0, binning_y=0, roi=roi)


def quaternion(yaw: float) -> object:
    return T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=math.sin(yaw / 2),
                                             w=math.cos(yaw / 2))


def pose(stamp: int, x: float, y: float, yaw: float) -> object:
    return T[POSE](header=header(stamp, 'map'), pose=T['geometry_msgs/msg/Pose'](
        position=T['geometry_msgs/msg/Point'](x=x, y=y, z=0.0), orientation=quaternion(yaw)))


def transform(stamp: int, parent: str, child: str, xyz: tuple[float, float, float],
              q: tuple[float, float, float, float]) -> object:
    return T['geometry_msgs/msg/TransformStamped'](
        header=header(stamp, parent), child_frame_id=child,
        transform=T['geometry_msgs/msg/Transform'](
            translation=T['geometry_msgs/msg/Vector3'](x=xyz[0], y=xyz[1], z=xyz[2]),
            rotation=T['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3])))


def planar(stamp: int, parent: str, child: str, x: float, y: float, yaw: float) -> object:
    return transform(stamp, parent, child, (x, y, 0.0),
                     (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)))


OPTICAL = (-0.5, 0.5, -0.5, 0.5)  # base_link -> optical camera frame


def write_bag(path: Path, messages: list[tuple[str, str, int, object]]) -> Path:
    """Write ``(topic, msgtype, stamp, message)`` in the given order."""
    with BagWriter(path) as bag:
        connections = {}
        for topic, msgtype, stamp, msg in messages:
            if topic not in connections:
                connections[topic] = bag.add_topic(topic, msgtype)
            bag.write(connections[topic], stamp, msg)
    return path


def exploration_messages(n: int = 3, images: list[object] | None = None,
                         poses: list[object] | None = None, with_info: bool = True,
                         with_truth: bool = True, with_tf: bool = False,
                         with_static: bool = True) -> list[tuple[str, str, int, object]]:
    """``n`` images 1 s apart at (i, 2i) with yaw 0.5 i, and what the flags ask for.

    ``/tf_static`` (first): the optical camera 0.1 m ahead of base_link, 1.2 m up.
    """
    out = []
    if with_static:
        out.append(('/tf_static', TF, T0, T[TF](transforms=[
            transform(T0, 'base_link', 'camera', (0.1, 0.0, 1.2), OPTICAL)])))
    for i in range(n):
        t = T0 + i * 10**9
        out.append(('/camera/image_raw', IMAGE, t, images[i] if images else image(t)))
        if with_info:
            out.append(('/camera/camera_info', INFO, t, info(t)))
        if with_truth:
            out.append(('/ground_truth/pose', POSE, t,
                        poses[i] if poses else pose(t, float(i), 2.0 * i, 0.5 * i)))
        if with_tf:
            out.append(('/tf', TF, t, T[TF](transforms=[
                planar(t, 'map', 'base_link', float(i), 2.0 * i, 0.5 * i)])))
    return out


