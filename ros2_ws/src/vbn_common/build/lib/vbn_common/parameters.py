"""What the project's nodes share about their parameters (pure Python, no rclpy).

rclpy ignores a ``-p NAME:=VALUE`` (or a parameters-file entry) that the node never
declares, so a misspelt name goes unnoticed and the node then complains about something
else; :func:`unknown_parameters` names it with the closest declared name. Both nodes
describe each parameter by its settings dataclass's docstring (:func:`attribute_docs`).
"""
from __future__ import annotations

import difflib

__all__ = ['attribute_docs', 'unknown_parameters']

#: Parameters rclpy declares on every node.
_ROS_PARAMETERS = frozenset({'use_sim_time', 'start_type_description_service'})


def unknown_parameters(given: list[str] | set[str], known: set[str]) -> str:
    """Say which given parameters the node does not have, with the closest known names.

    Args:
        given: Parameter names from the command line or a parameters file.
        known: The node's parameters.

    Returns:
        ``''`` when every name is known, else one line such as ``unknown parameter
        'dbb' (did you mean 'db'?)``.
    """
    unknown = sorted(set(given) - set(known) - _ROS_PARAMETERS)
    if not unknown:
        return ''
    parts = []
    for name in unknown:
        close = difflib.get_close_matches(name, sorted(known), n=1, cutoff=0.6)
        parts.append(f"'{name}'" + (f" (did you mean '{close[0]}'?)" if close else ''))
    label = 'parameter' if len(unknown) == 1 else 'parameters'
    return f'unknown {label} {", ".join(parts)}'


def attribute_docs(cls: type) -> dict[str, str]:
    """Return ``{attribute: description}`` from the ``Attributes:`` block of a docstring.

    An attribute is a line indented by eight spaces, ``name: text``; lines indented
    further continue it; the block ends at the first blank line.
    """
    docs: dict[str, str] = {}
    inside, name = False, ''
    for line in (cls.__doc__ or '').splitlines():
        stripped = line.strip()
        if stripped == 'Attributes:':
            inside = True
            continue
        if not inside:
            continue
        if not stripped:
            break
        head, sep, text = stripped.partition(':')
        if sep and head.isidentifier() and line.startswith(' ' * 8) \
                and not line.startswith(' ' * 12):
            name = head
            docs[name] = text.strip()
        elif name:
            docs[name] += ' ' + stripped
    return docs
