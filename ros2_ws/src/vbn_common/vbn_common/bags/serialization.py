"""CDR serialization of ROS 2 Jazzy messages with rosbags' typestore (no rclpy).

:data:`TYPESTORE` holds the ROS 2 Jazzy message definitions shipped with rosbags;
:func:`serialize` and :func:`deserialize` convert between rosbags message objects and
CDR bytes as a DDS payload carries them; :func:`msgdef_hash` gives the RIHS01 type
hash of a message definition that the typestore does not know (a custom type recorded
by ``vbn record``).
"""
from __future__ import annotations

from typing import Any

from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from vbn_common.errors import VbnCommonError

__all__ = [
    'TYPESTORE',
    'deserialize',
    'first_line',
    'msgdef_hash',
    'normalize_msgtype',
    'serialize',
]

#: The ROS 2 Jazzy message definitions shipped with rosbags.
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


def first_line(error: BaseException) -> str:
    """Return the first line of an error's text (its class name when it has none)."""
    text = str(error).strip().splitlines()
    return text[0] if text else type(error).__name__


def normalize_msgtype(msgtype: str) -> str:
    """``pkg/Type`` -> ``pkg/msg/Type``; ``pkg/msg/Type`` unchanged.

    Raises:
        VbnCommonError: The name has neither form.
    """
    parts = msgtype.strip().split('/')
    if len(parts) == 2 and all(parts):
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3 and all(parts):
        return msgtype.strip()
    raise VbnCommonError(f'invalid message type name {msgtype!r} (expected pkg/msg/Type)')


def msgdef_hash(msgdef: str, msgtype: str) -> str:
    """Compute the RIHS01 type hash of a ``ros2msg`` definition (dependencies included).

    Args:
        msgdef: The definition text, with the definitions it depends on.
        msgtype: The type it defines, ``pkg/msg/Type``.

    Returns:
        The hash, ``RIHS01_<64 hex digits>``.

    Raises:
        VbnCommonError: The definition does not parse.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    try:
        store.register(get_types_from_msg(msgdef, msgtype))
        return store.hash_rihs01(msgtype)
    except Exception as error:  # noqa: BLE001 - parser errors of many kinds
        raise VbnCommonError(
            f'cannot parse the definition of {msgtype!r}: {first_line(error)}') from error


def serialize(message: object, msgtype: str, typestore: Any = None) -> bytes:
    """Serialize a rosbags message object to CDR bytes (little endian).

    The result is padded with zeros to a multiple of 4 bytes, as a DDS serialized
    payload is: Fast DDS pads every message it delivers that way, so a bag of
    padded messages is what ``ros2 bag record`` (or ``vbn record``) writes, and a
    play-to-record round trip reproduces it byte for byte. Every CDR reader
    ignores the trailing padding.

    Args:
        message: A message object of ``typestore.types[msgtype]``.
        msgtype: Its type, ``pkg/msg/Type`` (``pkg/Type`` is accepted).
        typestore: A rosbags typestore; default the Jazzy :data:`TYPESTORE`.

    Returns:
        The CDR bytes, encapsulation header included.

    Raises:
        VbnCommonError: Unknown type or a message that does not fit it.
    """
    store = typestore or TYPESTORE
    msgtype = normalize_msgtype(msgtype)
    if msgtype not in store.fielddefs:
        raise VbnCommonError(f'unknown message type {msgtype!r}')
    try:
        data = bytes(store.serialize_cdr(message, msgtype))
    except Exception as error:  # noqa: BLE001 - rosbags raises many kinds here
        raise VbnCommonError(
            f'cannot serialize {type(message).__name__} as {msgtype}: {error}') from error
    return data + bytes(-len(data) % 4)


def deserialize(rawdata: bytes | memoryview, msgtype: str, typestore: Any = None) -> Any:
    """Deserialize CDR bytes into a rosbags message object.

    Args:
        rawdata: The CDR message.
        msgtype: Its type, ``pkg/msg/Type``.
        typestore: A rosbags typestore; default the Jazzy :data:`TYPESTORE`.

    Returns:
        The message object.

    Raises:
        VbnCommonError: Unknown type or data that is not such a message.
    """
    store = typestore or TYPESTORE
    msgtype = normalize_msgtype(msgtype)
    if msgtype not in store.fielddefs:
        raise VbnCommonError(
            f'unknown message type {msgtype!r}: not a ROS 2 Jazzy type known to rosbags')
    try:
        return store.deserialize_cdr(rawdata, msgtype)
    except Exception as error:  # noqa: BLE001 - corrupted data fails in many ways
        raise VbnCommonError(
            f'cannot deserialize {len(rawdata)} bytes as {msgtype}: {error}') from error
