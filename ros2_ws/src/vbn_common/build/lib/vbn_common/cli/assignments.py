"""``--set NAME=VALUE`` options, shared by the commands that take settings by name."""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from vbn_common.errors import VbnError

__all__ = ['parse_assignments']


def parse_assignments(items: Iterable[str]) -> dict[str, Any]:
    """Return ``NAME=VALUE`` items as a dict, each value read as a YAML scalar.

    ``k=8`` gives an int, ``ratio=0.8`` a float, ``flag=true`` a bool, ``ratio=null``
    None; text YAML cannot read stays text.

    Raises:
        VbnError: An item without ``=`` or without a name.

    Example:
        >>> parse_assignments(['classes.gamma=2', 'decomposition.algorithm=best'])
        {'classes.gamma': 2, 'decomposition.algorithm': 'best'}
    """
    import yaml

    values: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition('=')
        if not sep or not name.strip():
            raise VbnError(f'--set wants NAME=VALUE, got {item!r}')
        try:
            values[name.strip()] = yaml.safe_load(text.strip())
        except yaml.YAMLError:
            values[name.strip()] = text.strip()
    return values
