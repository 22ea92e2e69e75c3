"""Messages as YAML, the way ``ros2 topic echo`` prints them.

``rosidl_runtime_py`` (which ``ros2 topic echo`` uses) is not in the pip-installed
ROS 2, so this re-implements its ``message_to_ordereddict`` + YAML dump: fields in
declaration order, nested messages indented, arrays and strings longer than
``truncate_length`` cut with a ``'...'`` element (``ros2 topic echo``'s default is
128, so an image's ``data`` prints its first 128 values), or with ``no_arr`` every
array replaced by ``'<sequence type: uint8, length: 16384>'``.
"""
from __future__ import annotations

import array
import sys
from typing import Any

import numpy as np
import yaml

__all__ = ['message_to_dict', 'message_to_yaml']


def _is_message(value: Any) -> bool:
    return hasattr(type(value), 'get_fields_and_field_types')


def _array_text(field_type: str, length: int) -> str:
    base = field_type.split('<')[-1].rstrip('>').replace('sequence', '')
    base = base.split('[')[0]
    if field_type.startswith('sequence') or field_type.endswith('[]'):
        return f'<sequence type: {base}, length: {length}>'
    return f'<array type: {base}[{length}]>'


def _convert(value: Any, field_type: str, truncate_length: int | None, no_arr: bool,
             no_str: bool) -> Any:
    if _is_message(value):
        return message_to_dict(value, truncate_length=truncate_length, no_arr=no_arr,
                               no_str=no_str)
    if isinstance(value, (array.array, np.ndarray, list, tuple)):
        if no_arr:
            return _array_text(field_type, len(value))
        items = value.tolist() if isinstance(value, (array.array, np.ndarray)) else list(value)
        inner = field_type.split('<', 1)[1].rsplit('>', 1)[0] if '<' in field_type else \
            field_type.split('[')[0]
        out = [_convert(v, inner, truncate_length, no_arr, no_str) for v in
               (items if truncate_length is None else items[:truncate_length])]
        if truncate_length is not None and len(items) > truncate_length:
            out.append('...')
        return out
    if isinstance(value, bytes):
        if len(value) == 1:  # a `byte` field
            return value[0]
        items = list(value)
        if truncate_length is not None and len(items) > truncate_length:
            return items[:truncate_length] + ['...']
        return items
    if isinstance(value, str):
        if no_str:
            return f'<string length: {len(value)}>'
        if truncate_length is not None and len(value) > truncate_length:
            return value[:truncate_length] + '...'
        return value
    if isinstance(value, np.generic):
        return value.item()
    return value


def message_to_dict(msg: Any, *, truncate_length: int | None = 128, no_arr: bool = False,
                    no_str: bool = False) -> dict[str, Any]:
    """Convert an rclpy message to a dict of plain Python values, fields in order.

    Args:
        msg: An instance of a generated ROS 2 message class.
        truncate_length: Cut longer arrays, bytes and strings (None: print all).
        no_arr: Replace every array by its type and length.
        no_str: Replace every string by its length.
    """
    out: dict[str, Any] = {}
    for name, field_type in msg.get_fields_and_field_types().items():
        out[name] = _convert(getattr(msg, name), field_type, truncate_length, no_arr, no_str)
    return out


class _Dumper(yaml.SafeDumper):
    """Keep insertion order and print lists as block sequences."""


def message_to_yaml(msg: Any, *, truncate_length: int | None = 128, no_arr: bool = False,
                    no_str: bool = False) -> str:
    """Format a message as ``ros2 topic echo`` does (without the ``---`` separator)."""
    data = message_to_dict(msg, truncate_length=truncate_length, no_arr=no_arr, no_str=no_str)
    return yaml.dump(data, Dumper=_Dumper, allow_unicode=True, width=sys.maxsize,
                     default_flow_style=False, sort_keys=False)
