"""Offered QoS profiles as rosbag2 records them (rosbags ``Qos`` values).

A bag records, per topic, the QoS its publishers offered, so that playing it back
offers the same. rosbag2 (metadata version 8, ROS 2 Jazzy) stores them as a YAML
list in ``metadata.yaml`` and in the MCAP channel's ``offered_qos_profiles``
metadata; rosbags' own parser and dumper read and write that text.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import ReaderError
from rosbags.rosbag2.metadata import dump_qos_v8, parse_qos

from vbn_common.errors import VbnCommonError

__all__ = ['default_qos', 'dump_qos_yaml', 'parse_qos_profiles', 'qos_from_channel_metadata']


def default_qos(
    *,
    reliability: str = 'reliable',
    durability: str = 'volatile',
    depth: int = 10,
) -> Qos:
    """Make a rosbags ``Qos`` for an offered profile, keep-last history.

    Args:
        reliability: ``'reliable'`` or ``'best_effort'``.
        durability: ``'volatile'`` or ``'transient_local'``.
        depth: History depth.

    Returns:
        The profile, with rmw's "infinite" deadline, lifespan and lease duration.

    Raises:
        VbnCommonError: An unknown reliability or durability.
    """
    try:
        rel = QosReliability[reliability.upper()]
        dur = QosDurability[durability.upper()]
    except KeyError as error:
        raise VbnCommonError(f'unknown QoS setting {error}') from error
    infinite = QosTime(0x7FFFFFFF, 0xFFFFFFFF)  # rmw's "infinite" as rosbag2 stores it
    return Qos(QosHistory.KEEP_LAST, depth, rel, dur, infinite, infinite,
               QosLiveliness.AUTOMATIC, infinite, False)


def parse_qos_profiles(profiles: str | Sequence[Qos | dict[str, Any]] | None) -> list[Qos]:
    """Normalize offered QoS profiles (YAML string, dicts or ``Qos``) to ``Qos``.

    Args:
        profiles: rosbag2's YAML text, a list of ``Qos`` or QoS dicts, or None.

    Returns:
        The profiles (empty for None or an empty input).

    Raises:
        VbnCommonError: The profiles cannot be parsed.
    """
    if not profiles:
        return []
    if isinstance(profiles, str):
        try:
            return parse_qos(profiles)
        except (ReaderError, KeyError, TypeError) as error:
            raise VbnCommonError(f'invalid offered QoS profiles: {error}') from error
    out: list[Qos] = []
    for item in profiles:
        if isinstance(item, Qos):
            out.append(item)
        else:
            try:
                out.extend(parse_qos([item]))  # type: ignore[list-item]
            except (ReaderError, KeyError, TypeError) as error:
                raise VbnCommonError(f'invalid offered QoS profile: {error}') from error
    return out


def dump_qos_yaml(profiles: Sequence[Qos]) -> str:
    """Dump offered QoS profiles as rosbag2 (version 8) YAML text."""
    return dump_qos_v8(list(profiles))


def qos_from_channel_metadata(metadata: Mapping[str, str]) -> list[Qos]:
    """Read the offered QoS of an MCAP channel's metadata; [] when absent or unreadable.

    QoS is optional information: a damaged or foreign profile text must not make a
    channel unreadable.
    """
    text = metadata.get('offered_qos_profiles', '')
    if not text:
        return []
    try:
        return parse_qos(text)
    except Exception:  # noqa: BLE001 - QoS is optional information
        return []
