"""Write an exploration bag with its images' estimated poses (``vbn estimate-poses``).

Every topic of the input is copied byte for byte (same types, same offered QoS, same
log times); ``/estimated/pose`` (``geometry_msgs/PoseStamped``, frame ``map``, the
pose of ``base_link``) is added with one message per image whose pose was estimated,
stamped with the image's stamp. The bag appears atomically (the project's
:class:`~vbn_common.bags.BagWriter`): a failure leaves nothing at ``out``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from vbn_common import names
from vbn_common.bags import BagWriter, default_qos, messages, open_bag
from vbn_common.bags.serialization import TYPESTORE
from vbn_common.geometry.frames import wrap_angle
from visibility_builder.errors import VisibilityBuilderError

__all__ = ['write_estimated_bag']


def write_estimated_bag(source: str | Path, out: str | Path, stamps_ns: np.ndarray,
                        poses: np.ndarray) -> int:
    """Copy ``source`` to ``out`` and add ``/estimated/pose`` at ``stamps_ns``.

    Args:
        source: The exploration bag.
        out: The bag to create (must not exist).
        stamps_ns: ``(n,)`` image stamps.
        poses: ``(n, 3)`` base poses ``(x, y, yaw)`` in ``map``; rows with NaN are
            not written.

    Returns:
        The number of estimated poses written.
    """
    out = Path(out)
    if out.exists():
        raise VisibilityBuilderError(f'{out} exists already, not overwriting')
    stamps_ns = np.asarray(stamps_ns, np.int64)
    poses = np.asarray(poses, float).reshape(-1, 3)
    ok = np.isfinite(poses).all(axis=1)
    pending = sorted(zip(stamps_ns[ok].tolist(), range(int(ok.sum())), strict=True))
    chosen = poses[ok]
    written = 0
    with open_bag(source) as bag, BagWriter(out) as writer:
        if names.ESTIMATED_POSE in bag.topics:
            raise VisibilityBuilderError(f'bag {source} has {names.ESTIMATED_POSE} already')
        connections = {name: _copy_topic(writer, name, info)
                       for name, info in bag.topics.items()}
        estimated = writer.add_topic(names.ESTIMATED_POSE, 'geometry_msgs/msg/PoseStamped',
                                     [default_qos()])
        k = 0

        def flush(until: int | None) -> None:
            nonlocal k, written
            while k < len(pending) and (until is None or pending[k][0] <= until):
                stamp, row = pending[k]
                pose = chosen[row]
                pose = np.array([pose[0], pose[1], float(wrap_angle(pose[2]))])
                writer.write(estimated, stamp, messages.pose_stamped_message(stamp, pose))
                written += 1
                k += 1

        for topic, _, stamp, raw in bag.messages():
            flush(stamp)
            writer.write_raw(connections[topic], stamp, raw)
        flush(None)
    return written


def _copy_topic(writer: BagWriter, name: str, info: object) -> object:
    """Add a topic like ``info`` (its type, QoS, and definition when not a Jazzy type)."""
    qos = info.qos_profiles or None
    if info.msgtype in TYPESTORE.fielddefs or not info.msgdef:
        return writer.add_topic(name, info.msgtype, qos)
    return writer.add_topic(name, info.msgtype, qos, msgdef=info.msgdef)
